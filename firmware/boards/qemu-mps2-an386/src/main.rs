//! imucal firmware for QEMU's mps2-an386: the firmware core with the host link on UART0 and a
//! simulated IMU fed on UART1 (see the crate's README for how to run it).
#![no_std]
#![no_main]

use core::cell::RefCell;

use cortex_m_rt::entry;
use defmt_semihosting as _;
use imucal_board_qemu_mps2_an386::{
    exit,
    ram_flash::{RamNorFlash, SLOT_SIZE},
    sensor::{FeedClock, FeedImu, FeedReceiver},
    uart::{CmsdkUart, UartPort},
    BAUD,
};
use imucal_firmware::device::{Device, DeviceError, DeviceInfo};
use imucal_firmware::store::ParamStore;
use imucal_protocol::{DeviceId, FirmwareVersion, SensorSet};

/// The emulated board has no unique id: this fixed one reads "MPS2" followed by the image number.
const DEVICE_ID: u64 = 0x4D50_5332_0386;

/// Parses a decimal version component at compile time.
const fn parse_u16(text: &str) -> u16 {
    let bytes = text.as_bytes();
    let mut value: u16 = 0;
    let mut i = 0;
    while i < bytes.len() {
        value = value * 10 + (bytes[i] - b'0') as u16;
        i += 1;
    }
    value
}

const FIRMWARE_VERSION: FirmwareVersion = FirmwareVersion {
    major: parse_u16(env!("CARGO_PKG_VERSION_MAJOR")),
    minor: parse_u16(env!("CARGO_PKG_VERSION_MINOR")),
    patch: parse_u16(env!("CARGO_PKG_VERSION_PATCH")),
};

#[entry]
fn main() -> ! {
    let Some((flash, start)) = RamNorFlash::take() else {
        defmt::error!("parameter storage already claimed");
        exit(false)
    };
    let (Some(link), Some(feed_uart)) = (
        CmsdkUart::take(UartPort::Uart0, BAUD),
        CmsdkUart::take(UartPort::Uart1, BAUD),
    ) else {
        defmt::error!("UART already claimed");
        exit(false)
    };
    defmt::info!(
        "imucal on mps2-an386: {} start; waiting for the sensor feed on UART1",
        start
    );

    // Like probing a chip at boot: nothing runs until the feed has announced its configuration.
    let feed = RefCell::new(FeedReceiver::new(feed_uart));
    let scales = loop {
        let mut receiver = feed.borrow_mut();
        receiver.pump();
        if let Some(scales) = receiver.scales() {
            break scales;
        }
    };
    defmt::info!("sensor feed up at {=f32} Hz", scales.sample_rate_hz);

    let store = match ParamStore::new(flash, 0, SLOT_SIZE as u32) {
        Ok(store) => store,
        Err(_) => {
            // `new` fails only on geometry; the error's sentence needs core::fmt, kept out here.
            defmt::error!(
                "parameter store: the two {=usize}-byte slots do not fit the RAM flash",
                SLOT_SIZE
            );
            exit(false)
        }
    };
    let info = DeviceInfo {
        device_id: DeviceId::from_u64(DEVICE_ID),
        firmware_version: FIRMWARE_VERSION,
        sensors: SensorSet {
            accel: true,
            gyro: true,
            mag: true,
            temp: true,
        },
    };
    let imu = FeedImu::new(&feed, scales);
    let clock = FeedClock::new(&feed);
    let mut device: Device<_, _, _, _> = match Device::new(imu, link, store, clock, info) {
        Ok(device) => device,
        Err(DeviceError::InvalidSampleRate(rate)) => {
            // defmt formats the float on the host, so no float formatting is linked in.
            defmt::error!(
                "the sensor feed announced {=f32} Hz; feed a rate between 1 Hz and 100 kHz",
                rate
            );
            exit(false)
        }
    };
    loop {
        device.poll();
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    // The message would need core::fmt; the location identifies the panic.
    match info.location() {
        Some(at) => defmt::error!("panic at {=str}:{=u32}", at.file(), at.line()),
        None => defmt::error!("panic"),
    }
    exit(false)
}
