//! The simulated MotionCal sketch board over its pseudo-terminal: the lines it prints, and its
//! packet receiver (stores a good packet and echoes it, ignores a corrupted one, finds a packet
//! after a false start). Packets are built here by hand from the documented layout.

use std::io::Write;
use std::time::{Duration, Instant};

use imucal_hil_sim::motioncal_serve::MotionCalHandle;

/// Simulated seconds per wall second: a packet needs 68 sketch loops (0.68 s simulated).
const SPEED: f64 = 20.0;

fn packet(values: [f32; 16]) -> Vec<u8> {
    let mut bytes = vec![117u8, 84];
    for v in values {
        bytes.extend(v.to_le_bytes());
    }
    let mut crc: u16 = 0xFFFF;
    for &b in &bytes {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xA001
            } else {
                crc >> 1
            };
        }
    }
    bytes.extend(crc.to_le_bytes());
    bytes
}

const VALUES: [f32; 16] = [
    0.25, -0.125, 0.5, 0.01, -0.02, 0.03, 12.5, -30.25, 7.125, 48.5, 0.97, 1.03, 0.99, 0.02, -0.01,
    0.015,
];

fn open(handle: &MotionCalHandle) -> Box<dyn serialport::SerialPort> {
    serialport::new(handle.port_path(), 115_200)
        .timeout(Duration::from_millis(20))
        .open()
        .expect("the pty opens")
}

/// Reads whatever arrives for `wall` and returns it as text.
fn read_for(port: &mut dyn serialport::SerialPort, wall: Duration) -> String {
    let end = Instant::now() + wall;
    let mut text = Vec::new();
    let mut buffer = [0u8; 4096];
    while Instant::now() < end {
        if let Ok(n) = port.read(&mut buffer) {
            text.extend_from_slice(&buffer[..n]);
        }
    }
    String::from_utf8_lossy(&text).into_owned()
}

fn wait_for_store(handle: &MotionCalHandle, count: u32) -> bool {
    let end = Instant::now() + Duration::from_secs(10);
    while Instant::now() < end {
        if handle.stored_count() >= count {
            return true;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    false
}

#[test]
fn board_prints_raw_and_uni_lines_in_the_sketch_scaling_ending_in_crlf() {
    let handle = MotionCalHandle::start(3, SPEED).unwrap();
    let mut port = open(&handle);
    let text = read_for(port.as_mut(), Duration::from_millis(300));
    let lines: Vec<&str> = text.split("\r\n").collect();
    assert!(lines.len() > 20, "too few lines: {}", lines.len());
    // Every line break is \r\n: no bare \n or \r remain inside the split lines.
    assert!(lines.iter().all(|l| !l.contains(['\r', '\n'])));
    let mut pairs = 0;
    for w in lines.windows(2) {
        let (Some(raw), Some(uni)) = (w[0].strip_prefix("Raw:"), w[1].strip_prefix("Uni:")) else {
            continue;
        };
        let raw: Vec<i64> = raw.split(',').map(|v| v.parse().unwrap()).collect();
        let uni: Vec<f64> = uni.split(',').map(|v| v.parse().unwrap()).collect();
        assert_eq!((raw.len(), uni.len()), (9, 9));
        // Uni prints 2 decimals (±0.005 m/s², ±0.005 µT) and 4 for the gyro (±5e-5 rad/s);
        // Raw truncates, so they agree within those plus one count.
        for i in 0..3 {
            let a = uni[i] * 8192.0 / 9.8;
            assert!((raw[i] as f64 - a).abs() <= 0.005 * 8192.0 / 9.8 + 1.0);
            let g = uni[3 + i].to_degrees() * 16.0;
            assert!((raw[3 + i] as f64 - g).abs() <= 5e-5f64.to_degrees() * 16.0 + 1.0);
            assert!((raw[6 + i] as f64 - uni[6 + i] * 10.0).abs() <= 0.05 + 1.0);
        }
        let g_norm = (uni[0] * uni[0] + uni[1] * uni[1] + uni[2] * uni[2]).sqrt();
        // An uncalibrated consumer accelerometer at rest reads gravity within a few percent.
        assert!((g_norm - 9.81).abs() < 1.0, "{g_norm}");
        pairs += 1;
    }
    assert!(pairs > 10, "only {pairs} Raw/Uni pairs");
}

#[test]
fn packet_written_over_the_pty_is_stored_and_echoed_in_cal1_and_cal2() {
    let handle = MotionCalHandle::start(4, SPEED).unwrap();
    let mut port = open(&handle);
    port.write_all(&packet(VALUES)).unwrap();
    assert!(wait_for_store(&handle, 1), "the packet was not stored");
    let stored = handle.eeprom().unwrap();
    assert_eq!(stored.accel_zerog, [0.25, -0.125, 0.5]);
    assert_eq!(stored.gyro_zerorate, [0.01, -0.02, 0.03]);
    assert_eq!(stored.mag_hardiron, [12.5, -30.25, 7.125]);
    assert_eq!(stored.mag_field, 48.5);
    assert_eq!(
        stored.mag_softiron,
        [0.97, 0.02, -0.01, 0.02, 1.03, 0.015, -0.01, 0.015, 0.99]
    );
    // Cal1 and Cal2 come every 100 loops (1 s simulated).
    let text = read_for(port.as_mut(), Duration::from_millis(250));
    assert!(text.contains("Wrote calibration"), "no store message");
    assert!(
        text.contains("Cal1:0.250,-0.125,0.500,0.010,-0.020,0.030,12.500,-30.250,7.125,48.500\r\n"),
        "no Cal1 echo in {text:.400}"
    );
    assert!(
        text.contains("Cal2:0.9700,0.0200,-0.0100,0.0200,1.0300,0.0150,-0.0100,0.0150,0.9900\r\n")
    );
}

#[test]
fn corrupted_packet_is_ignored() {
    let handle = MotionCalHandle::start(5, SPEED).unwrap();
    let mut port = open(&handle);
    let mut bad = packet(VALUES);
    bad[30] ^= 0x10;
    port.write_all(&bad).unwrap();
    // 68 loops to read it plus margin, at SPEED: about 0.1 s wall.
    std::thread::sleep(Duration::from_millis(400));
    assert!(handle.sim_time_s() > 2.0);
    assert_eq!(handle.stored_count(), 0);
    assert!(handle.eeprom().is_none());
}

#[test]
fn packet_after_a_false_start_and_split_writes_is_found_by_resynchronising() {
    let handle = MotionCalHandle::start(6, SPEED).unwrap();
    let mut port = open(&handle);
    let good = packet(VALUES);
    // Noise, then a false start (signature and 20 junk bytes), then the packet in two writes.
    let mut stream = vec![0x00, 0x75, 0x11];
    stream.extend([117, 84]);
    stream.extend([0xAB; 20]);
    stream.extend(&good[..30]);
    port.write_all(&stream).unwrap();
    std::thread::sleep(Duration::from_millis(30));
    port.write_all(&good[30..]).unwrap();
    assert!(wait_for_store(&handle, 1), "the packet was not found");
    assert_eq!(handle.eeprom().unwrap().mag_field, 48.5);
    assert_eq!(handle.stored_count(), 1);
}
