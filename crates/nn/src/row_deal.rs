//! Work dealt to threads with the numbers of one thread: [`RowDealer`], the rows of several
//! batched passes ("slots", e.g. an ensemble's members, each on its own rows) in equal blocks;
//! [`map_side_by_side`], independent items (an ensemble's members in training) one per task.

use rayon::prelude::*;

/// Work (multiply-adds over all slots' rows) below which the slots run one after the other on
/// one thread: handing rows to another thread costs a few microseconds.
pub const PARALLEL_MIN_MACS: usize = 1 << 20;

/// Rows per vector of the widest kernels (16 `f32` lanes): a slot's rows are cut at multiples of
/// it, so no block adds a half-empty vector.
pub const ROW_ALIGN: usize = 16;

/// One block of a slot's rows (`start..end` of the slot's rows) with its own buffers `B`.
#[derive(Debug, Default)]
pub struct RowBlock<B> {
    /// The slot the rows belong to.
    pub slot: usize,
    /// First row of the block, within the slot's rows.
    pub start: usize,
    /// One past the last row of the block.
    pub end: usize,
    /// The block's buffers (reused from deal to deal).
    pub bufs: B,
}

/// Deals the rows of several slots to threads and runs the blocks side by side. Its blocks and
/// their buffers are kept between deals, so a repeated pass of one size allocates nothing.
#[derive(Debug)]
pub struct RowDealer<B> {
    blocks: Vec<RowBlock<B>>,
    group_lens: Vec<usize>,
    dealt: usize,
}

impl<B> Default for RowDealer<B> {
    fn default() -> Self {
        Self {
            blocks: Vec::new(),
            group_lens: Vec::new(),
            dealt: 0,
        }
    }
}

impl<B: Default + Send> RowDealer<B> {
    /// Threads worth dealing `macs` multiply-adds to: rayon's pool from [`PARALLEL_MIN_MACS`] on,
    /// else one.
    pub fn threads_for(macs: usize) -> usize {
        if macs >= PARALLEL_MIN_MACS {
            rayon::current_num_threads()
        } else {
            1
        }
    }

    /// Deals the rows of `slots` slots (`count(i)` rows for slot `i`) to `threads` groups of about
    /// equal rows, in slot and row order, and returns the blocks dealt. A slot's rows are cut only
    /// at multiples of [`ROW_ALIGN`] and only where `apart(slot, whole, part)` holds for both
    /// resulting blocks (each block then gets exactly the numbers of the slot's whole pass, e.g.
    /// [`crate::Mlp::rows_run_apart`]); otherwise the group boundary moves to the nearer end of
    /// that slot. Empty slots get no block.
    pub fn deal(
        &mut self,
        slots: usize,
        count: impl Fn(usize) -> usize,
        threads: usize,
        apart: impl Fn(usize, usize, usize) -> bool,
    ) -> &mut [RowBlock<B>] {
        fn push<B: Default>(
            blocks: &mut Vec<RowBlock<B>>,
            k: usize,
            slot: usize,
            start: usize,
            end: usize,
        ) {
            if blocks.len() == k {
                blocks.push(RowBlock::default());
            }
            let bl = &mut blocks[k];
            (bl.slot, bl.start, bl.end) = (slot, start, end);
        }
        let Self {
            blocks,
            group_lens,
            dealt,
        } = self;
        let total: usize = (0..slots).map(&count).sum();
        let threads = threads.max(1);
        group_lens.clear();
        *dealt = 0;
        let (mut group, mut done, mut in_group) = (0, 0, 0);
        for slot in 0..slots {
            let n = count(slot);
            let mut start = 0;
            while start < n {
                let rest = n - start;
                // Rows dealt when this group should end.
                let boundary = total * (group + 1) / threads;
                let last_group = group + 1 == threads;
                let (end, close) = if last_group || done + rest <= boundary {
                    (n, !last_group && done + rest == boundary)
                } else {
                    let room = boundary.saturating_sub(done);
                    let cut = (room + ROW_ALIGN / 2) / ROW_ALIGN * ROW_ALIGN;
                    if cut > 0 && cut < rest && apart(slot, n, cut) && apart(slot, n, rest - cut) {
                        (start + cut, true)
                    } else if in_group == 0 || 2 * room >= rest {
                        (n, true)
                    } else {
                        // The whole rest goes to the next group.
                        group_lens.push(in_group);
                        (group, in_group) = (group + 1, 0);
                        continue;
                    }
                };
                push(blocks, *dealt, slot, start, end);
                *dealt += 1;
                (done, in_group, start) = (done + end - start, in_group + 1, end);
                if close {
                    group_lens.push(in_group);
                    (group, in_group) = (group + 1, 0);
                }
            }
        }
        if in_group > 0 {
            group_lens.push(in_group);
        }
        &mut blocks[..*dealt]
    }

    /// The blocks of the latest deal, in slot and row order.
    pub fn blocks_mut(&mut self) -> &mut [RowBlock<B>] {
        &mut self.blocks[..self.dealt]
    }

    /// Runs `f` on every block of the latest deal, the groups side by side ([`crate::join`]),
    /// each group's blocks in order on one thread. The first error is returned.
    pub fn run<E: Send>(
        &mut self,
        f: &(impl Fn(&mut RowBlock<B>) -> Result<(), E> + Sync),
    ) -> Result<(), E> {
        run_groups(&mut self.blocks[..self.dealt], &self.group_lens, f)
    }
}

/// `f` on every item, side by side on rayon's threads when there are two or more of both, else one
/// after the other; the results in item order. Items that share nothing get the numbers they
/// would get one after the other.
pub fn map_side_by_side<T: Send, R: Send>(
    items: &mut [T],
    f: impl Fn(&mut T) -> R + Sync + Send,
) -> Vec<R> {
    if items.len() > 1 && rayon::current_num_threads() > 1 {
        items.par_iter_mut().map(f).collect()
    } else {
        items.iter_mut().map(f).collect()
    }
}

/// [`RowDealer::run`] on `blocks` cut into groups of `group_lens[g]` consecutive blocks.
fn run_groups<B: Send, E: Send>(
    blocks: &mut [RowBlock<B>],
    group_lens: &[usize],
    f: &(impl Fn(&mut RowBlock<B>) -> Result<(), E> + Sync),
) -> Result<(), E> {
    match group_lens {
        [] => Ok(()),
        [_] => blocks.iter_mut().try_for_each(f),
        _ => {
            let (left, right) = group_lens.split_at(group_lens.len() / 2);
            let (bl, br) = blocks.split_at_mut(left.iter().sum());
            let (a, b) = crate::join(|| run_groups(bl, left, f), || run_groups(br, right, f));
            a.and(b)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng as _;
    use tandem_core::seeding::rng_from_seed;

    /// The blocks dealt, as `(slot, start, end)` per group.
    fn dealt(
        counts: &[usize],
        threads: usize,
        apart: impl Fn(usize, usize, usize) -> bool,
    ) -> Vec<Vec<(usize, usize, usize)>> {
        let mut dealer = RowDealer::<()>::default();
        let n = dealer
            .deal(counts.len(), |i| counts[i], threads, apart)
            .len();
        assert_eq!(dealer.group_lens.iter().sum::<usize>(), n);
        let mut it = dealer.blocks[..n].iter().map(|b| (b.slot, b.start, b.end));
        dealer
            .group_lens
            .iter()
            .map(|&l| it.by_ref().take(l).collect())
            .collect()
    }

    #[test]
    fn rows_are_dealt_in_equal_aligned_blocks_where_they_may_be_cut() {
        let yes = |_: usize, _: usize, _: usize| true;
        // Five slots of 100 rows on two threads: the middle one is cut at 48 rows.
        assert_eq!(
            dealt(&[100; 5], 2, yes),
            vec![
                vec![(0, 0, 100), (1, 0, 100), (2, 0, 48)],
                vec![(2, 48, 100), (3, 0, 100), (4, 0, 100)]
            ]
        );
        // Where the cut would change the numbers, the nearer end of the slot is the boundary.
        let no = |_: usize, _: usize, _: usize| false;
        assert_eq!(
            dealt(&[100; 5], 2, no),
            vec![
                vec![(0, 0, 100), (1, 0, 100), (2, 0, 100)],
                vec![(3, 0, 100), (4, 0, 100)]
            ]
        );
        let only_whole = |_: usize, whole: usize, part: usize| part * 2 >= whole;
        assert_eq!(
            dealt(&[100, 30, 100], 2, only_whole),
            vec![vec![(0, 0, 100), (1, 0, 30)], vec![(2, 0, 100)]]
        );
        // One thread: every non-empty slot whole, in one group.
        assert_eq!(dealt(&[7, 0, 9], 1, yes), vec![vec![(0, 0, 7), (2, 0, 9)]]);
        // Random slot sizes, 1-4 threads: the blocks cover each slot's rows once and in order,
        // no more groups than threads, cuts on multiples of 16, groups within a block of equal.
        let mut rng = rng_from_seed(2);
        for _ in 0..300 {
            let k = rng.random_range(1..8);
            let counts: Vec<usize> = (0..k).map(|_| rng.random_range(0..3000)).collect();
            let threads = rng.random_range(1..5);
            let groups = dealt(&counts, threads, yes);
            assert!(groups.len() <= threads && groups.iter().all(|g| !g.is_empty()));
            let flat: Vec<_> = groups.concat();
            let mut next = vec![0; k];
            for &(slot, start, end) in &flat {
                assert_eq!(start, next[slot], "{counts:?}");
                assert!(end > start && (end == counts[slot] || end % ROW_ALIGN == 0));
                next[slot] = end;
            }
            assert_eq!(next, counts);
            let total: usize = counts.iter().sum();
            for g in &groups {
                let rows: usize = g.iter().map(|&(_, a, b)| b - a).sum();
                let largest = counts.iter().max().unwrap();
                assert!(
                    rows <= total / threads + ROW_ALIGN.max(*largest),
                    "{counts:?}"
                );
            }
        }
    }

    /// Every block runs once, whatever the threads, and the first error comes back.
    #[test]
    fn every_block_runs_once_on_any_number_of_threads() {
        for threads in [1, 2, 3] {
            crate::on_threads(threads, || {
                let mut dealer = RowDealer::<Vec<usize>>::default();
                dealer.deal(4, |i| 40 * (i + 1), threads, |_, _, _| true);
                let fill = |bl: &mut RowBlock<Vec<usize>>| -> Result<(), ()> {
                    bl.bufs.clear();
                    bl.bufs.extend(bl.start..bl.end);
                    Ok(())
                };
                dealer.run(&fill).unwrap();
                for slot in 0..4 {
                    let rows: Vec<usize> = dealer
                        .blocks_mut()
                        .iter()
                        .filter(|bl| bl.slot == slot)
                        .flat_map(|bl| bl.bufs.iter().copied())
                        .collect();
                    assert_eq!(rows, (0..40 * (slot + 1)).collect::<Vec<_>>());
                }
                let fail = |bl: &mut RowBlock<Vec<usize>>| {
                    if bl.slot == 2 {
                        Err(bl.slot)
                    } else {
                        Ok(())
                    }
                };
                assert_eq!(dealer.run(&fail), Err(2));
            });
        }
    }

    #[test]
    fn items_side_by_side_come_back_in_order() {
        for threads in [1, 2, 3] {
            let mut items: Vec<usize> = (0..7).collect();
            let out = crate::on_threads(threads, || {
                map_side_by_side(&mut items, |i| {
                    *i += 10;
                    *i * 2
                })
            });
            assert_eq!(out, (10..17).map(|i| i * 2).collect::<Vec<_>>());
            assert_eq!(items, (10..17).collect::<Vec<_>>());
        }
    }
}
