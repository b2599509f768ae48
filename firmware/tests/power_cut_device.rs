//! Power cuts through the whole device, with the fault-injecting RAM flash: at every erase and
//! program step of a parameter commit (`WriteParams` + `CommitParams`, and `ResetParams`), twice
//! in a row across reboots, and during boot. After each reboot `GetParams` must return exactly
//! the old or the new set, and the device must accept the next commit.
//!
//! Boot does no flash writes at all (the store only scans both slots and takes the newest valid
//! one), so a cut during boot cannot change the flash: the boot tests show that no boot writes,
//! and that a slot torn at any byte, in any program order, is ignored.

mod bench;

use bench::*;
use imucal_firmware::store::HEADER_LEN;
use imucal_protocol::{CalibrationSet, ErrorCode, RequestBody, ResponseBody};

/// A flash holding `fitted_set()` as the only committed set (sequence 1, slot 0), with the step
/// counter cleared.
fn flash_with_old_set() -> Flash {
    let mut bench = Bench::new();
    assert!(matches!(
        bench.write_and_commit(&fitted_set()),
        ResponseBody::ParamStatus(_)
    ));
    let mut flash = bench.into_flash();
    flash.restore_power();
    flash
}

/// A different valid set, with extended terms so that its payload is longer than the old one's.
fn newer_set() -> CalibrationSet {
    let mut set = full_set();
    set.created_unix_s += 3600;
    set.accel.b = [0.2, -0.1, 0.0];
    set
}

/// Flash steps (sector erases and program words) of one commit of `set` on `flash`.
fn commit_steps(flash: &Flash, set: &CalibrationSet) -> u32 {
    let mut bench = Bench::boot(flash.clone());
    assert!(matches!(
        bench.write_and_commit(set),
        ResponseBody::ParamStatus(_)
    ));
    bench.into_flash().steps()
}

/// What a rebooted device reports: `Some(true)` new, `Some(false)` old, `None` anything else.
fn after_reboot(flash: Flash, old: &CalibrationSet, new: &CalibrationSet) -> (Bench, Option<bool>) {
    let mut bench = Bench::boot(flash).reboot();
    let active = bench.get_params();
    let which = if active == *new {
        Some(true)
    } else if active == *old {
        Some(false)
    } else {
        None
    };
    (bench, which)
}

/// Commit `new` on `flash` with the power cut at `cut`; returns the flash and whether the
/// device reported success.
fn commit_with_cut(flash: &Flash, cut: u32, new: &CalibrationSet) -> (Flash, bool) {
    let mut flash = flash.clone();
    flash.cut_power_at_step(Some(cut));
    let mut bench = Bench::boot(flash);
    let reply = bench.write_and_commit(new);
    let succeeded = match reply {
        ResponseBody::ParamStatus(_) => true,
        ResponseBody::Error(ErrorCode::FlashError) => false,
        other => panic!("cut at step {cut}: unexpected reply {other:?}"),
    };
    (bench.into_flash(), succeeded)
}

#[test]
fn a_power_cut_at_every_step_of_a_commit_leaves_the_old_or_the_new_set() {
    let prepared = flash_with_old_set();
    let (old, new) = (fitted_set(), newer_set());
    let total = commit_steps(&prepared, &new);
    // Two 1 KiB sectors erased, then the 20-byte header and the payload in 4-byte words.
    assert!(total > 2 + HEADER_LEN as u32 / 4, "{total} steps");
    let (mut kept_old, mut got_new) = (0, 0);
    for cut in 0..=total {
        let (flash, succeeded) = commit_with_cut(&prepared, cut, &new);
        // `cut == total` is past the last step: the commit completes.
        assert_eq!(succeeded, cut == total, "cut at step {cut}");
        let (mut bench, which) = after_reboot(flash, &old, &new);
        match which {
            Some(true) => got_new += 1,
            Some(false) => kept_old += 1,
            None => panic!("cut at step {cut}: neither the old nor the new set is active"),
        }
        assert!(
            !succeeded || which == Some(true),
            "a commit reported done must survive"
        );
        let ResponseBody::Status(status) = bench.request(RequestBody::Status) else {
            panic!("Status failed");
        };
        assert_eq!(status.active_seq, if which == Some(true) { 2 } else { 1 });
        // The device keeps working: the next commit succeeds and survives a reboot.
        let mut third = fitted_set();
        third.gyro.b = [0.001, 0.001, 0.001];
        assert!(matches!(
            bench.write_and_commit(&third),
            ResponseBody::ParamStatus(_)
        ));
        assert_eq!(bench.reboot().get_params(), third);
    }
    eprintln!(
        "commit: {} cut points ({total} steps + completion), old kept {kept_old}, new {got_new}",
        total + 1
    );
    // Every cut before the last step keeps the old set: the header is programmed last.
    assert_eq!((kept_old, got_new), (total, 1));
}

#[test]
fn a_power_cut_at_every_step_of_a_reset_leaves_the_old_set_or_the_identity() {
    let prepared = flash_with_old_set();
    let (old, identity) = (fitted_set(), CalibrationSet::identity());
    let mut probe = Bench::boot(prepared.clone());
    assert!(matches!(
        probe.request(RequestBody::ResetParams),
        ResponseBody::ParamStatus(_)
    ));
    let total = probe.into_flash().steps();
    for cut in 0..=total {
        let mut flash = prepared.clone();
        flash.cut_power_at_step(Some(cut));
        let mut bench = Bench::boot(flash);
        let reply = bench.request(RequestBody::ResetParams);
        let succeeded = matches!(reply, ResponseBody::ParamStatus(_));
        assert!(
            succeeded || reply == ResponseBody::Error(ErrorCode::FlashError),
            "{reply:?}"
        );
        let (_, which) = after_reboot(bench.into_flash(), &old, &identity);
        assert_eq!(which, Some(succeeded), "cut at step {cut}");
    }
    eprintln!("reset: {} cut points", total + 1);
}

#[test]
fn two_power_cuts_in_a_row_across_reboots_never_lose_the_set() {
    // A cut leaves the inactive slot half erased or half written; the retry after the reboot
    // writes over that debris and may be cut again, at any step.
    let prepared = flash_with_old_set();
    let (old, new) = (fitted_set(), newer_set());
    let total = commit_steps(&prepared, &new);
    let mut pairs = 0;
    for first in 0..total {
        let (mut debris, succeeded) = commit_with_cut(&prepared, first, &new);
        assert!(!succeeded);
        debris.restore_power();
        let retry_total = commit_steps(&debris, &new);
        assert_eq!(retry_total, total, "the retry takes the same steps");
        for second in 0..=retry_total {
            let (flash, succeeded) = commit_with_cut(&debris, second, &new);
            let (_, which) = after_reboot(flash, &old, &new);
            assert_eq!(
                which,
                Some(succeeded),
                "cuts at steps {first} then {second}"
            );
            pairs += 1;
        }
    }
    eprintln!("double cuts: {pairs} pairs of cut points");
    assert_eq!(pairs, total * (total + 1));
}

#[test]
fn boot_and_read_only_requests_never_write_the_flash() {
    // Flash states to boot from: erased, one set, two sets, and every torn commit.
    let prepared = flash_with_old_set();
    let new = newer_set();
    let mut states = vec![Flash::new(), prepared.clone()];
    let (mut two_sets, _) = commit_with_cut(&prepared, u32::MAX, &new);
    two_sets.restore_power();
    states.push(two_sets);
    for cut in 0..commit_steps(&prepared, &new) {
        let (mut torn, _) = commit_with_cut(&prepared, cut, &new);
        torn.restore_power();
        states.push(torn);
    }
    let boots = states.len();
    for (index, state) in states.into_iter().enumerate() {
        let before = state.memory().to_vec();
        let mut flash = state;
        // Any erase or program during boot would be step 0 and would cut the power.
        flash.cut_power_at_step(Some(0));
        let mut bench = Bench::boot(flash);
        bench.get_params();
        bench.request(RequestBody::Status);
        bench.request(RequestBody::hello());
        bench.run_polls(100);
        let flash = bench.into_flash();
        assert!(flash.is_powered(), "state {index}: boot wrote to the flash");
        assert_eq!(flash.steps(), 0, "state {index}");
        assert!(flash.memory() == before.as_slice(), "state {index}");
    }
    eprintln!("read-only boots: {boots} flash states");
}

#[test]
fn a_slot_torn_at_any_byte_in_any_program_order_is_ignored_at_boot() {
    let prepared = flash_with_old_set();
    let (old, new) = (fitted_set(), newer_set());
    // The complete new slot image, as a finished commit leaves it (slot 1 starts at SLOT_SIZE).
    let (finished, _) = commit_with_cut(&prepared, u32::MAX, &new);
    let slot = SLOT_SIZE as usize;
    let image = finished.memory()[slot..2 * slot].to_vec();
    assert_ne!(image[..HEADER_LEN], [0xFF; HEADER_LEN]);
    let mut boots = 0;
    // Front to back (header first, the opposite of the store's order), with the next byte torn
    // (its low nibble still erased), and back to front (payload first, header last).
    for len in 0..=slot {
        for torn_next in [false, true] {
            for header_last in [false, true] {
                let mut flash = prepared.clone();
                let target = &mut flash.memory_mut()[slot..2 * slot];
                let range = if header_last {
                    slot - len..slot
                } else {
                    0..len
                };
                target[range.clone()].copy_from_slice(&image[range.clone()]);
                let next = if header_last {
                    (slot - len).checked_sub(1)
                } else {
                    Some(len).filter(|&at| at < slot)
                };
                if let (true, Some(at)) = (torn_next, next) {
                    target[at] = image[at] | 0x0F;
                }
                let complete = target[..] == image[..];
                let (_, which) = after_reboot(flash, &old, &new);
                assert_eq!(
                    which,
                    Some(complete),
                    "len {len}, torn {torn_next}, header last {header_last}"
                );
                boots += 1;
            }
        }
    }
    eprintln!("torn slots: {boots} boots over {slot} byte positions");
}

#[test]
fn a_newest_stored_set_that_no_longer_validates_falls_back_to_the_older_set() {
    // As after a firmware update that tightened a limit: the newest slot is intact and decodes,
    // but validation refuses it. The device must boot on the older valid set, not the identity.
    let flash = flash_with_old_set();
    let mut refused = fitted_set();
    refused.accel.a = [[9.8, 0.0, 0.0], [0.0, 9.8, 0.0], [0.0, 0.0, 9.8]];
    let mut buffer = [0u8; imucal_protocol::PARAMS_MAX_ENCODED];
    let bytes = postcard::to_slice(&refused, &mut buffer).expect("a set encodes");
    let mut store = imucal_firmware::store::ParamStore::new(flash, 0, SLOT_SIZE).expect("layout");
    assert_eq!(store.write(bytes), Ok(2), "stored behind the device's back");
    let mut bench = Bench::boot(store.into_flash());
    assert_eq!(bench.get_params(), fitted_set());
    let ResponseBody::Status(status) = bench.request(RequestBody::Status) else {
        panic!("Status request failed");
    };
    assert_eq!(
        (status.active_crc, status.active_seq),
        (fitted_set().crc32(), 1)
    );
    // The next commit is the newest set, across a reboot.
    assert!(matches!(
        bench.write_and_commit(&newer_set()),
        ResponseBody::ParamStatus(_)
    ));
    assert_eq!(bench.reboot().get_params(), newer_set());
}
