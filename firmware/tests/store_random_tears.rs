//! The parameter store under random power cuts, in the manner of `sequential-storage`'s fuzzing:
//! many seeded iterations, each cutting a write at a random step with a random *tear* (a
//! program step that cleared only some of its bits, an erase that set only some) and *marginal
//! bits* (cells left between states, which read back differently on every read). After each cut
//! the board reboots; the store must then load exactly the old set or exactly the new one
//! (the old one whenever the new one is not intact), and keep working.

use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use imucal_firmware::store::ParamStore;

const CAPACITY: usize = 4096;
const SLOT: u32 = 2048;

/// xorshift64*: small, seeded, reproducible.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    fn byte(&mut self) -> u8 {
        (self.next() >> 56) as u8
    }
}

#[derive(Debug, Clone, Copy)]
struct PowerLost;

impl NorFlashError for PowerLost {
    fn kind(&self) -> NorFlashErrorKind {
        NorFlashErrorKind::Other
    }
}

/// NOR flash (program clears bits, erase sets a sector to 0xFF) whose power fails at a chosen
/// step, tearing that step at random and leaving marginal bits behind.
struct TearingFlash {
    memory: Vec<u8>,
    /// Per byte, the bits that read back at random.
    marginal: Vec<u8>,
    steps: u32,
    cut_at: Option<u32>,
    powered: bool,
    rng: Rng,
}

impl TearingFlash {
    fn new(seed: u64) -> Self {
        Self {
            memory: vec![0xFF; CAPACITY],
            marginal: vec![0; CAPACITY],
            steps: 0,
            cut_at: None,
            powered: true,
            rng: Rng(seed | 1),
        }
    }

    /// `Err` once the power is gone; `Ok(true)` for the step that the cut tears.
    fn step(&mut self) -> Result<bool, PowerLost> {
        if !self.powered {
            return Err(PowerLost);
        }
        let torn = self.cut_at == Some(self.steps);
        self.steps += 1;
        if torn {
            self.powered = false;
        }
        Ok(torn)
    }

    fn reboot(&mut self) {
        self.powered = true;
        self.cut_at = None;
        self.steps = 0;
    }

    /// Of the bits in `changing`, a random subset becomes marginal (about one torn step in two
    /// leaves any).
    fn leave_marginal(&mut self, at: usize, changing: u8) {
        if self.rng.below(2) == 0 {
            self.marginal[at] |= changing & self.rng.byte() & self.rng.byte();
        }
    }
}

impl ErrorType for TearingFlash {
    type Error = PowerLost;
}

impl ReadNorFlash for TearingFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), PowerLost> {
        let start = offset as usize;
        for (i, out) in bytes.iter_mut().enumerate() {
            let weak = self.marginal[start + i];
            *out = (self.memory[start + i] & !weak) | (self.rng.byte() & weak);
        }
        Ok(())
    }

    fn capacity(&self) -> usize {
        CAPACITY
    }
}

impl NorFlash for TearingFlash {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = 1024;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), PowerLost> {
        for sector in (from..to).step_by(Self::ERASE_SIZE) {
            let torn = self.step()?;
            for at in sector as usize..sector as usize + Self::ERASE_SIZE {
                if torn {
                    // Some cells reached 1, others not yet.
                    let rising = !self.memory[at];
                    self.memory[at] |= self.rng.byte();
                    self.leave_marginal(at, rising);
                } else {
                    self.memory[at] = 0xFF;
                    self.marginal[at] = 0;
                }
            }
        }
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), PowerLost> {
        for (word, chunk) in bytes.chunks(Self::WRITE_SIZE).enumerate() {
            let torn = self.step()?;
            for (i, &value) in chunk.iter().enumerate() {
                let at = offset as usize + word * Self::WRITE_SIZE + i;
                if torn {
                    // Only some of the bits to clear are cleared.
                    let falling = self.memory[at] & !value;
                    self.memory[at] &= value | self.rng.byte();
                    self.leave_marginal(at, falling);
                } else {
                    self.memory[at] &= value;
                }
            }
        }
        Ok(())
    }
}

fn payload(rng: &mut Rng) -> Vec<u8> {
    let len = 1 + rng.below(700) as usize;
    (0..len).map(|_| rng.byte()).collect()
}

#[test]
fn random_tears_and_marginal_bits_leave_exactly_the_old_or_the_new_set() {
    const ITERATIONS: u64 = 3000;
    let mut rng = Rng(0x1234_5678_9abc_def1);
    let (mut kept_old, mut got_new, mut first_write_lost) = (0, 0, 0);
    let mut buffer = [0u8; 2048];
    for iteration in 0..ITERATIONS {
        let mut flash = TearingFlash::new(rng.next());
        // Zero to three earlier sets; the last is the "old" one.
        let mut old = None;
        let mut store = ParamStore::new(flash, 0, SLOT).expect("layout fits");
        for _ in 0..rng.below(4) {
            let earlier = payload(&mut rng);
            store.write(&earlier).expect("power is on");
            old = Some(earlier);
        }
        flash = store.into_flash();
        flash.reboot();
        // A slot of two sectors plus at most (20 + 700) / 4 program words: cut anywhere in
        // there, or (past the end) not at all.
        flash.cut_at = Some(rng.below(2 + 181 + 8) as u32);
        let new = payload(&mut rng);
        let mut store = ParamStore::new(flash, 0, SLOT).expect("layout fits");
        let completed = store.write(&new).is_ok();
        let mut flash = store.into_flash();
        flash.reboot();

        let mut store = ParamStore::new(flash, 0, SLOT).expect("layout fits");
        let loaded = store
            .load_newest(&mut buffer, |bytes| Some(bytes.to_vec()))
            .map(|(bytes, _)| bytes);
        let context = format!("iteration {iteration}, write completed: {completed}");
        match &loaded {
            Some(bytes) if *bytes == new => got_new += 1,
            Some(bytes) => {
                assert_eq!(Some(bytes), old.as_ref(), "{context}: foreign content");
                assert!(!completed, "{context}: a completed write was lost");
                kept_old += 1;
            }
            None => {
                assert!(old.is_none() && !completed, "{context}: nothing loaded");
                first_write_lost += 1;
            }
        }
        // The store keeps working after the reboot.
        let next = payload(&mut rng);
        store.write(&next).expect("power is on");
        let mut store = ParamStore::new(store.into_flash(), 0, SLOT).expect("layout fits");
        let reloaded = store.load_newest(&mut buffer, |bytes| Some(bytes.to_vec()));
        assert_eq!(
            reloaded.map(|(b, _)| b),
            Some(next),
            "{context}: next write"
        );
    }
    // Both outcomes occur, so the assertions above were exercised both ways.
    assert!(
        kept_old > 100 && got_new > 100,
        "{kept_old} old, {got_new} new"
    );
    println!(
        "{ITERATIONS} random cuts: {got_new} new set, {kept_old} old set kept, {first_write_lost} first write lost (no old set)"
    );
}
