//! A counting global allocator for the zero-allocation tests. It wraps the system allocator
//! and counts two ways:
//! - per thread ([`so_far`], [`during`]): what the calling thread allocated, so the harness's
//!   other threads do not disturb a count;
//! - inside realtime steps on every thread ([`in_rt_steps`]): allocations made while a thread
//!   runs a cycle of a task group, as marked by the activities
//!   ([`hytask::rt::activity::in_rt_step`]), the daemon's `SCHED_FIFO` servo thread included.
//!   The first such allocation's backtrace is kept ([`first_rt_backtrace`]) so a failure says
//!   where it came from.
//!
//! Include with `mod counting_alloc;` in a test binary: it installs itself as that binary's
//! global allocator.
#![allow(dead_code)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::backtrace::Backtrace;
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;

struct Counting;

thread_local! {
    static ALLOCS: Cell<u64> = const { Cell::new(0) };
    /// Set while this thread captures a backtrace (which allocates) from inside the allocator.
    static IN_HOOK: Cell<bool> = const { Cell::new(false) };
}

static RT_ALLOCS: AtomicU64 = AtomicU64::new(0);
static FIRST_RT: OnceLock<Backtrace> = OnceLock::new();

fn count() {
    let _ = ALLOCS.try_with(|c| c.set(c.get() + 1));
    if hytask::rt::activity::in_rt_step() && !IN_HOOK.try_with(Cell::get).unwrap_or(true) {
        RT_ALLOCS.fetch_add(1, Ordering::Relaxed);
        if FIRST_RT.get().is_none() {
            let _ = IN_HOOK.try_with(|h| h.set(true));
            // Unresolved: symbols are looked up when printed, on the test's thread.
            let _ = FIRST_RT.set(Backtrace::force_capture());
            let _ = IN_HOOK.try_with(|h| h.set(false));
        }
    }
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

/// Allocations and frees made inside realtime steps so far, on every thread.
pub fn in_rt_steps() -> u64 {
    RT_ALLOCS.load(Ordering::Relaxed)
}

/// Where the first allocation inside a realtime step came from, if there was one.
pub fn first_rt_backtrace() -> Option<String> {
    FIRST_RT.get().map(|b| b.to_string())
}
