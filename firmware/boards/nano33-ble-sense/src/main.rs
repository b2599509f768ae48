//! imucal firmware for the Arduino Nano 33 BLE Sense: the firmware core with the LSM9DS1 (rev 1)
//! or, built with the `rev2` feature, the BMI270 + BMM150 (Rev2) on the internal I²C bus, the host link on USB CDC-ACM and the parameter store in the top two
//! flash pages (see the crate's README for how to flash and use it).
#![no_std]
#![no_main]

use cortex_m_rt::entry;
use defmt_rtt as _;
use imucal_board_nano33_ble_sense::{
    clock::TimerClock,
    hex_u64,
    param_flash::{self, ParamFlashError, SLOT_SIZE},
    usb_link::{DwtCycles, UsbSerialLink},
    USB_MANUFACTURER, USB_PID, USB_PRODUCT, USB_VID,
};
use imucal_firmware::device::{Device, DeviceError, DeviceInfo};
use imucal_firmware::store::ParamStore;
use imucal_protocol::{DeviceId, FirmwareVersion, SensorSet};
use nrf52840_hal::clocks::Clocks;
use nrf52840_hal::gpio::{p0, p1, DriveConfig, Level};
use nrf52840_hal::pac;
use nrf52840_hal::twim::{self, Twim};

mod sensor;
use nrf52840_hal::usbd::{UsbPeripheral, Usbd};
use usb_device::bus::UsbBusAllocator;
use usb_device::device::{StringDescriptors, UsbDeviceBuilder, UsbVidPid};
use usbd_serial::{SerialPort, USB_CLASS_CDC};

/// Core clock after reset, Hz (the nRF52840 always runs its Cortex-M4 at 64 MHz).
const CPU_HZ: u32 = 64_000_000;
/// Wait after switching on VDD_ENV before talking to the sensors, which first load their
/// trimming values (tens of milliseconds); 50 ms also lets the switched supply settle.
const SENSOR_POWER_UP_MS: u32 = 50;

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

/// Halts after a start-up failure that needs a new firmware or hardware; the reason was logged.
fn halt() -> ! {
    loop {
        cortex_m::asm::wfi();
    }
}

#[entry]
fn main() -> ! {
    let (Some(mut core), Some(p)) = (cortex_m::Peripherals::take(), pac::Peripherals::take())
    else {
        defmt::error!("peripherals already taken");
        halt()
    };
    // The DWT cycle counter times USB write stalls.
    core.DCB.enable_trace();
    core.DWT.enable_cycle_counter();

    // USB needs the 32 MHz crystal; it also makes TIMER1's microseconds crystal-accurate.
    let clocks = Clocks::new(p.CLOCK).enable_ext_hfosc();
    let clock = TimerClock::start(p.TIMER1);

    let port0 = p0::Parts::new(p.P0);
    let port1 = p1::Parts::new(p.P1);
    let _led = port0.p0_13.into_push_pull_output(Level::High);
    // VDD_ENV sources the sensors' current; Arduino's variant drives it with high drive too.
    let _sensor_power = port0
        .p0_22
        .into_push_pull_output_drive(Level::High, DriveConfig::HighDrive0HighDrive1);
    let _i2c_pullups = port1
        .p1_00
        .into_push_pull_output_drive(Level::High, DriveConfig::Standard0HighDrive1);
    cortex_m::asm::delay(SENSOR_POWER_UP_MS * (CPU_HZ / 1000));

    let i2c = Twim::new(
        p.TWIM0,
        twim::Pins {
            sda: port0.p0_14.into_floating_input().degrade(),
            scl: port0.p0_15.into_floating_input().degrade(),
        },
        twim::Frequency::K400,
    );
    let imu = sensor::configure(i2c);

    let flash = match param_flash::take(p.NVMC) {
        Ok(flash) => flash,
        Err(ParamFlashError::AlreadyTaken) => {
            defmt::error!("parameter flash already taken");
            halt()
        }
        Err(ParamFlashError::BadRegion { start, len }) => {
            defmt::error!(
                "PARAMS region at {=usize:#x} ({=usize} bytes) is not two aligned 4 KiB pages; \
                 fix memory-bootloader.x or memory-no-bootloader.x",
                start,
                len
            );
            halt()
        }
    };
    let store = match ParamStore::new(flash, 0, SLOT_SIZE as u32) {
        Ok(store) => store,
        Err(_) => {
            // `new` fails only on geometry; the error's sentence needs core::fmt, kept out here.
            defmt::error!(
                "parameter store: two {=usize}-byte slots do not fit the PARAMS flash region",
                SLOT_SIZE
            );
            halt()
        }
    };

    let device_id = (u64::from(p.FICR.deviceid[1].read().bits()) << 32)
        | u64::from(p.FICR.deviceid[0].read().bits());
    let mut serial_text = [0u8; 16];
    let serial_number = hex_u64(device_id, &mut serial_text);

    let usb_bus = UsbBusAllocator::new(Usbd::new(UsbPeripheral::new(p.USBD, &clocks)));
    let serial = SerialPort::new(&usb_bus);
    let strings = StringDescriptors::default()
        .manufacturer(USB_MANUFACTURER)
        .product(USB_PRODUCT)
        .serial_number(serial_number);
    let usb_device = match UsbDeviceBuilder::new(&usb_bus, UsbVidPid(USB_VID, USB_PID))
        .strings(&[strings])
        .and_then(|builder| builder.max_packet_size_0(64))
    {
        Ok(builder) => builder.device_class(USB_CLASS_CDC).build(),
        Err(_) => {
            defmt::error!(
                "USB descriptor set-up rejected; check the string descriptors and EP0 size"
            );
            halt()
        }
    };
    let link = UsbSerialLink::new(usb_device, serial, DwtCycles);

    let info = DeviceInfo {
        device_id: DeviceId::from_u64(device_id),
        firmware_version: FIRMWARE_VERSION,
        sensors: SensorSet {
            accel: true,
            gyro: true,
            mag: true,
            temp: true,
        },
    };
    let mut device: Device<_, _, _, _> = match Device::new(imu, link, store, clock, info) {
        Ok(device) => device,
        Err(DeviceError::InvalidSampleRate(rate)) => {
            defmt::error!(
                "the sensor configuration gives {=f32} Hz; configure a rate between 1 Hz and 100 kHz",
                rate
            );
            halt()
        }
    };
    defmt::info!(
        "imucal on Nano 33 BLE Sense: USB {=u16:04x}:{=u16:04x}, serial {=str}",
        USB_VID,
        USB_PID,
        serial_number
    );
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
    halt()
}
