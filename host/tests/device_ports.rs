//! Opening ports: absent and busy ports give sentences that say what to do.

use imucal::device::{open_port, DeviceError};
use serialport::{SerialPort, TTYPort};

#[test]
fn an_absent_port_says_so_and_points_to_imucal_ports() {
    let error = open_port("/dev/ttyIMUCAL-absent").expect_err("no such device");
    assert!(matches!(error, DeviceError::NoSuchPort { .. }), "{error:?}");
    assert_eq!(
        error.to_string(),
        "no such port /dev/ttyIMUCAL-absent; run `imucal ports` to list the serial ports"
    );
}

#[test]
fn a_port_held_by_another_program_is_reported_busy() {
    let (_master, slave) = TTYPort::pair().expect("pseudo-terminals are available");
    let path = slave.name().expect("a pty slave has a path");
    let _first = open_port(&path).expect("the first open succeeds");
    let error = open_port(&path).expect_err("the second open is refused");
    assert!(matches!(error, DeviceError::PortBusy { .. }), "{error:?}");
    let message = error.to_string();
    assert!(message.contains(&path), "{message}");
    assert!(message.contains("in use by another program"), "{message}");
}
