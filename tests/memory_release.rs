//! `memory::release_freed`: memory freed in small blocks between live ones goes back to the
//! system (a process of its own, so that no other test allocates while the resident size is
//! read).

use antiradiance::memory::{current_rss_bytes, release_freed};

/// Blocks allocated, bytes each: 240 MB in all.
const BLOCKS: usize = 120_000;
const BLOCK_BYTES: usize = 2_000;

/// Every how many blocks one is kept: the freed ones lie between live ones (as the exact
/// couplings' per-receiver rows do once copied), so the allocator cannot hand them back by
/// shrinking its heaps from the top.
const KEEP_EVERY: usize = 16;

#[test]
fn small_blocks_freed_between_live_ones_leave_the_resident_memory() {
    if !antiradiance::memory::RELEASES_FREED {
        eprintln!("skipped: release_freed acts with glibc's allocator only");
        return;
    }
    let Some(before) = current_rss_bytes() else {
        eprintln!("skipped: the resident size is unknown");
        return;
    };
    // Allocated and freed on another thread, in an arena of its own as the solver's are.
    let kept = std::thread::spawn(|| {
        let mut blocks: Vec<Vec<u8>> = (0..BLOCKS).map(|i| vec![i as u8; BLOCK_BYTES]).collect();
        let kept: Vec<Vec<u8>> = blocks
            .iter_mut()
            .step_by(KEEP_EVERY)
            .map(std::mem::take)
            .collect();
        drop(blocks);
        kept
    })
    .join()
    .expect("the allocating thread ends");
    let held = current_rss_bytes().expect("resident size");
    let freed = (BLOCKS - BLOCKS / KEEP_EVERY) * BLOCK_BYTES;
    assert!(
        held > before + (freed / 2) as u64,
        "the freed blocks stay resident without a release: {before} -> {held} bytes"
    );
    assert!(release_freed(), "something was released");
    let after = current_rss_bytes().expect("resident size");
    assert!(
        held - after > (freed / 2) as u64,
        "{} of {freed} freed bytes left the resident memory ({held} -> {after})",
        held.saturating_sub(after)
    );
    // The kept blocks are intact.
    assert!(kept
        .iter()
        .enumerate()
        .all(|(k, b)| b.len() == BLOCK_BYTES && b[0] == (k * KEEP_EVERY) as u8));
}
