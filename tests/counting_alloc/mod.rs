//! A counting global allocator for the zero-allocation tests: it wraps the system allocator
//! and counts allocations and frees per thread, so the harness's other threads do not
//! disturb a count. Include with `mod counting_alloc;` in a test binary: it installs itself
//! as that binary's global allocator.
#![allow(dead_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    static ALLOCS: Cell<u64> = const { Cell::new(0) };
}

fn count() {
    let _ = ALLOCS.try_with(|c| c.set(c.get() + 1));
}

// SAFETY: forwards to the system allocator; only counts.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: same contract as ours.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        count();
        // SAFETY: same contract as ours.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: same contract as ours.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Allocations and frees so far on this thread.
pub fn so_far() -> u64 {
    ALLOCS.with(Cell::get)
}

/// Allocations (and frees) made by `f` on this thread.
pub fn during(f: impl FnOnce()) -> u64 {
    let before = so_far();
    f();
    so_far() - before
}
