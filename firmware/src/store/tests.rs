//! The store against a RAM flash: reboots, sequence wrap, bit flips, geometry, page-sized reads,
//! refused sets and a power cut at every step.

use super::*;
use crate::ram_flash::RamFlash;

/// A flash that only reads whole 256-byte pages.
struct ReadPages<F>(F);

impl<F: embedded_storage::nor_flash::ErrorType> embedded_storage::nor_flash::ErrorType
    for ReadPages<F>
{
    type Error = F::Error;
}

impl<F: NorFlash> embedded_storage::nor_flash::ReadNorFlash for ReadPages<F> {
    const READ_SIZE: usize = 256;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        assert!(
            offset.is_multiple_of(256) && bytes.len().is_multiple_of(256),
            "unaligned read"
        );
        self.0.read(offset, bytes)
    }
    fn capacity(&self) -> usize {
        self.0.capacity()
    }
}

impl<F: NorFlash> NorFlash for ReadPages<F> {
    const WRITE_SIZE: usize = F::WRITE_SIZE;
    const ERASE_SIZE: usize = F::ERASE_SIZE;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.0.erase(from, to)
    }
    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.0.write(offset, bytes)
    }
}

/// Deterministic payload bytes that differ between versions.
fn payload(version: u8, len: usize) -> std::vec::Vec<u8> {
    (0..len)
        .map(|i| (i as u8).wrapping_mul(31).wrapping_add(version))
        .collect()
}

fn active<F: NorFlash>(store: &mut ParamStore<F>) -> Option<std::vec::Vec<u8>> {
    let mut buffer = [0u8; 4096];
    let len = store.read_active(&mut buffer).ok()?;
    Some(buffer[..len].to_vec())
}

#[test]
fn a_written_set_survives_a_reboot_and_the_newest_wins() {
    let flash = RamFlash::<8192, 1024, 4>::new();
    let mut store = ParamStore::new(flash, 0, 2048).unwrap();
    assert_eq!(store.read_active(&mut [0; 64]), Err(StoreError::Empty));
    assert_eq!(store.write(&payload(1, 300)), Ok(1));
    assert_eq!(store.write(&payload(2, 301)), Ok(2));
    assert_eq!(store.write(&payload(3, 17)), Ok(3));
    let mut store = ParamStore::new(store.into_flash(), 0, 2048).unwrap();
    assert_eq!(store.active_sequence(), Some(3));
    assert_eq!(active(&mut store), Some(payload(3, 17)));
}

#[test]
fn sequence_order_survives_wrapping_past_u32_max() {
    assert!(is_newer(0, u32::MAX));
    assert!(is_newer(1, u32::MAX - 5));
    assert!(!is_newer(u32::MAX, 0));
    // Put a slot with sequence u32::MAX in place, then write over the wrap.
    let mut flash = RamFlash::<4096, 1024, 1>::new();
    let header = header_bytes(u32::MAX, &payload(7, 10));
    flash.write(0, &header).unwrap();
    flash.write(HEADER_LEN as u32, &payload(7, 10)).unwrap();
    let mut store = ParamStore::new(flash, 0, 1024).unwrap();
    assert_eq!(store.active_sequence(), Some(u32::MAX));
    assert_eq!(store.write(&payload(8, 10)), Ok(0));
    let mut store = ParamStore::new(store.into_flash(), 0, 1024).unwrap();
    assert_eq!(store.active_sequence(), Some(0));
    assert_eq!(active(&mut store), Some(payload(8, 10)));
}

#[test]
fn a_flipped_bit_invalidates_only_its_own_slot() {
    let mut store = ParamStore::new(RamFlash::<4096, 1024, 4>::new(), 0, 1024).unwrap();
    store.write(&payload(1, 100)).unwrap();
    store.write(&payload(2, 100)).unwrap();
    let mut flash = store.into_flash();
    // Slot 1 holds sequence 2; damage one payload bit there.
    flash.memory_mut()[1024 + HEADER_LEN + 50] ^= 0x10;
    let mut store = ParamStore::new(flash, 0, 1024).unwrap();
    assert_eq!(store.active_sequence(), Some(1));
    assert_eq!(active(&mut store), Some(payload(1, 100)));
}

#[test]
fn a_flash_that_reads_whole_256_byte_pages_still_checks_its_slots() {
    // READ_SIZE = CHUNK: each read window must still take at least one payload byte.
    let mut store = ParamStore::new(ReadPages(RamFlash::<8192, 2048, 4>::new()), 0, 2048).unwrap();
    assert_eq!(store.write(&payload(1, 700)), Ok(1));
    let mut store = ParamStore::new(store.into_flash(), 0, 2048).unwrap();
    assert_eq!(store.active_sequence(), Some(1));
    assert_eq!(active(&mut store), Some(payload(1, 700)));
}

#[test]
fn a_newest_set_the_caller_refuses_falls_back_to_the_older_one() {
    let mut store = ParamStore::new(RamFlash::<4096, 1024, 4>::new(), 0, 1024).unwrap();
    store.write(&payload(1, 100)).unwrap();
    store.write(&payload(2, 100)).unwrap();
    let mut store = ParamStore::new(store.into_flash(), 0, 1024).unwrap();
    let mut buffer = [0u8; 1024];
    // Refuse version 2 (as firmware with tighter limits would): version 1 becomes active.
    let loaded = store.load_newest(&mut buffer, |bytes| (bytes[0] == 1).then(|| bytes.to_vec()));
    assert_eq!(loaded, Some((payload(1, 100), 1)));
    assert_eq!(store.active_sequence(), Some(1));
    // The next write replaces the refused slot (taking its sequence number, 2): it is then
    // the newest set on the flash.
    assert_eq!(store.write(&payload(3, 50)), Ok(2));
    let mut store = ParamStore::new(store.into_flash(), 0, 1024).unwrap();
    assert_eq!(active(&mut store), Some(payload(3, 50)));
    // Refusing everything leaves nothing active, and a write still comes out newest.
    let mut store = ParamStore::new(store.into_flash(), 0, 1024).unwrap();
    assert_eq!(store.load_newest(&mut buffer, |_| None::<()>), None);
    assert_eq!(store.write(&payload(4, 60)), Ok(3));
    let mut store = ParamStore::new(store.into_flash(), 0, 1024).unwrap();
    assert_eq!(active(&mut store), Some(payload(4, 60)));
}

#[test]
fn oversized_payload_and_bad_layouts_are_refused() {
    let mut store = ParamStore::new(RamFlash::<4096, 1024, 4>::new(), 0, 1024).unwrap();
    assert_eq!(
        store.write(&[0; 1005]),
        Err(StoreError::TooLarge {
            len: 1005,
            max: 1004
        })
    );
    let geometry = |base, size| ParamStore::new(RamFlash::<4096, 1024, 4>::new(), base, size).err();
    assert_eq!(geometry(0, 1000), Some(StoreError::Geometry)); // not a sector multiple
    assert_eq!(geometry(512, 1024), Some(StoreError::Geometry)); // base off a sector boundary
    assert_eq!(geometry(2048, 2048), Some(StoreError::Geometry)); // past the end
    assert_eq!(geometry(u32::MAX - 1023, 1024), Some(StoreError::Geometry));
    // u32 overflow
}

/// Cut the power at every step of a write and check that a reboot finds old or new, intact.
/// Returns the number of cut points tested.
fn power_cut_at_every_step<const SIZE: usize, const ERASE: usize, const WRITE: usize>(
    slot_size: u32,
    old_len: usize,
    new_len: usize,
    writes_before: u8,
) -> u32 {
    // Prepare a flash holding `writes_before` earlier sets; the last is "old".
    let mut store = ParamStore::new(RamFlash::<SIZE, ERASE, WRITE>::new(), 0, slot_size).unwrap();
    for version in 1..=writes_before {
        store.write(&payload(version, old_len)).unwrap();
    }
    let mut prepared = store.into_flash();
    prepared.restore_power(); // count steps of the write under test only
    let old = (writes_before > 0).then(|| payload(writes_before, old_len));
    let new = payload(writes_before + 1, new_len);

    // The number of steps of an uninterrupted write bounds the cut points.
    let mut probe = ParamStore::new(prepared.clone(), 0, slot_size).unwrap();
    probe.write(&new).unwrap();
    let total_steps = probe.into_flash().steps();
    // One step per erased sector and per program word of the padded image: no step is skipped.
    let sectors = slot_size as usize / ERASE;
    let words = (HEADER_LEN + new_len).div_ceil(WRITE);
    assert_eq!(total_steps as usize, sectors + words);

    for cut in 0..=total_steps {
        let mut flash = prepared.clone();
        flash.cut_power_at_step(Some(cut));
        let mut store = ParamStore::new(flash, 0, slot_size).unwrap();
        let result = store.write(&new);
        assert_eq!(result.is_ok(), cut == total_steps, "cut at step {cut}");
        let mut flash = store.into_flash();
        flash.restore_power();
        let mut rebooted = ParamStore::new(flash, 0, slot_size).unwrap();
        let found = active(&mut rebooted);
        if cut == total_steps {
            assert_eq!(found.as_ref(), Some(&new), "completed write must be active");
        } else {
            assert!(
                found == old || found.as_ref() == Some(&new),
                "cut at step {cut}: {found:?}"
            );
        }
        // The device keeps working after the reboot.
        rebooted.write(&payload(99, 40)).unwrap();
        assert_eq!(active(&mut rebooted), Some(payload(99, 40)));
    }
    total_steps + 1
}

#[test]
fn power_cut_at_any_step_leaves_the_old_or_the_new_set() {
    let mut tested = 0;
    // Byte-programmable flash, slot of one sector, first write ever (old = none).
    tested += power_cut_at_every_step::<4096, 1024, 1>(1024, 0, 300, 0);
    // Byte-programmable, replacing an existing set (written into slot 1).
    tested += power_cut_at_every_step::<4096, 1024, 1>(1024, 200, 300, 1);
    // Word-programmable, replacing the set in slot 0 (two earlier writes), two sectors per slot.
    tested += power_cut_at_every_step::<8192, 512, 4>(1024, 280, 700, 2);
    // 8-byte program words, payload not a multiple of the word.
    tested += power_cut_at_every_step::<8192, 2048, 8>(2048, 333, 1001, 3);
    // (1 + 320) + (1 + 320) + (2 + 180) + (1 + 128) steps, each cut, plus 4 completed writes.
    assert_eq!(tested, 957);
    std::println!("power-cut points tested: {tested}");
}
