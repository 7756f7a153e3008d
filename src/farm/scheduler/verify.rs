//! Verification: columns rendered again on another worker and compared
//! bit for bit, a third worker to settle a dispute, and the conviction
//! of the worker found wrong (quarantined, every column it produced
//! rendered again).

use super::{Check, Sched};
use crate::render::PixelResult;

impl Sched {
    /// Drops the verifications no live worker but the producer could
    /// take; a dispute among them is settled against the producer.
    pub(super) fn drop_unverifiable(&mut self) {
        let live: Vec<usize> = (0..self.workers.len()).filter(|&i| self.workers[i].quarantined.is_none()).collect();
        let before = self.verify_queue.len();
        let checks = &self.checks;
        let mut unresolved = Vec::new();
        self.verify_queue.retain(|id| {
            let c = &checks[id];
            let ok = live.iter().any(|i| !c.excluded.contains(i));
            if !ok {
                unresolved.push(*id);
            }
            ok
        });
        self.stats.columns_unverified += (before - self.verify_queue.len()) as u32;
        for id in unresolved {
            // A dispute no third worker can settle: trust the verifier over
            // the producer (the column is rendered again by someone else).
            let c = self.checks.remove(&id).unwrap();
            if let Some((v, _)) = c.disputed {
                let why = format!(
                    "column {} differed bit for bit from {}'s, and no third worker could decide",
                    c.column, self.workers[v].name
                );
                self.convict(c.producer, why);
            }
        }
    }

    /// Whether column `column` is one of the `verify_fraction` rendered
    /// again (a hash of its job and column, the same on every run).
    pub(super) fn picked_for_verification(&self, column: u32) -> bool {
        if self.opts.verify_fraction <= 0.0 {
            return false;
        }
        let p = &self.parts[self.part_of(column)];
        let h = blake3::hash(format!("{}:{}", p.job_hash, column - p.offset).as_bytes());
        let u = u64::from_le_bytes(h.as_bytes()[..8].try_into().unwrap()) as f64 / u64::MAX as f64;
        u < self.opts.verify_fraction
    }

    /// Worker `w` delivered verification `check` of a column: equal to the
    /// stored column, it is verified; else a third worker decides, or, with
    /// a third opinion in, the one that disagrees is convicted.
    pub(super) fn finish_verify(&mut self, w: usize, check: u64, columns: Vec<Vec<PixelResult>>) {
        let Some(chk) = self.checks.remove(&check) else { return };
        let c = chk.column;
        // The producer may have been caught meanwhile (its columns
        // are being rendered again): nothing left to check.
        if self.producer[c as usize] != Some(chk.producer) {
            return;
        }
        let Some(mine) = columns.into_iter().next() else { return };
        let stored = self.columns[c as usize].clone().expect("a produced column");
        match chk.disputed {
            None if bitwise_equal(&stored, &mine) => self.stats.columns_verified += 1,
            None => {
                self.stats.verify_mismatches += 1;
                let third = (0..self.workers.len())
                    .any(|i| self.workers[i].quarantined.is_none() && i != chk.producer && i != w);
                if third {
                    // Two opinions differ: a third worker decides.
                    self.add_check(
                        Check {
                            column: c,
                            producer: chk.producer,
                            excluded: vec![chk.producer, w],
                            disputed: Some((w, mine)),
                        },
                        true,
                    );
                } else {
                    let why = format!(
                        "column {c} differed bit for bit when {} rendered it again (no third worker to decide)",
                        self.workers[w].name
                    );
                    self.convict(chk.producer, why);
                }
            }
            Some((v, theirs)) => {
                let name = self.workers[w].name.clone();
                if bitwise_equal(&stored, &mine) {
                    self.stats.columns_verified += 1;
                    let why = format!(
                        "its rendering of column {c} differed bit for bit from those of {} and {name}",
                        self.workers[chk.producer].name
                    );
                    self.convict(v, why);
                } else if bitwise_equal(&theirs, &mine) {
                    let why = format!(
                        "its column {c} differed bit for bit from those of {} and {name}",
                        self.workers[v].name
                    );
                    self.convict(chk.producer, why);
                } else {
                    let why = format!("three different renderings of column {c} ({name} was the third)");
                    self.convict(chk.producer, why.clone());
                    self.convict(v, why);
                }
            }
        }
    }

    /// Queues a verification: at the front if `urgent` (a dispute), else
    /// at the back.
    pub(super) fn add_check(&mut self, c: Check, urgent: bool) {
        let id = self.next_check;
        self.next_check += 1;
        self.checks.insert(id, c);
        if urgent {
            self.verify_queue.push_front(id);
        } else {
            self.verify_queue.push_back(id);
        }
    }

    /// Quarantines a worker caught with a wrong result and renders again
    /// every column it produced.
    fn convict(&mut self, w: usize, why: String) {
        self.quarantine(w, why);
        let mine: Vec<u32> = (0..self.width).filter(|&i| self.producer[i as usize] == Some(w)).collect();
        for i in mine {
            self.columns[i as usize] = None;
            self.producer[i as usize] = None;
            self.pending.insert(i);
            self.stats.columns_rendered -= 1;
            let k = self.part_of(i);
            let local = i - self.parts[k].offset;
            if let Some(j) = &mut self.parts[k].journal {
                if let Err(e) = j.retract(local) {
                    self.fatal = Some(e.into());
                }
            }
        }
        let checks = &self.checks;
        self.verify_queue.retain(|id| checks[id].producer != w);
        self.checks.retain(|_, c| c.producer != w);
    }
}

/// Whether two renderings of a column are the same bit for bit: every
/// value and sample count of every pixel.
fn bitwise_equal(a: &[PixelResult], b: &[PixelResult]) -> bool {
    let bits = |p: &PixelResult| -> Vec<u64> {
        p.xyz
            .iter()
            .chain(&p.xyz_direct)
            .chain(&p.xyz_stderr)
            .chain(&p.spectral)
            .chain(&p.spectral_stderr)
            .map(|v| v.to_bits())
            .chain(std::iter::once(p.samples as u64))
            .collect()
    };
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| bits(x) == bits(y))
}
