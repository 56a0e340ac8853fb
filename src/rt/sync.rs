//! Atomics, cells and locks used by the lock-free primitives, switched to `loom`'s model-checked
//! versions under `cfg(loom)`.
//!
//! Why: the data object, the buffers and the command queue are the only places where the
//! realtime core reasons about memory ordering by hand. Routing their atomics through this
//! module lets `RUSTFLAGS="--cfg loom" cargo test --lib rt::` explore every interleaving of
//! those exact implementations, not of a copy.

#[cfg(loom)]
pub(crate) use loom::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, AtomicUsize, Ordering};
#[cfg(loom)]
pub(crate) use loom::sync::{Arc, Mutex};

#[cfg(not(loom))]
pub(crate) use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, AtomicUsize, Ordering};
#[cfg(not(loom))]
pub(crate) use std::sync::{Arc, Mutex};

#[cfg(loom)]
pub(crate) use loom::cell::UnsafeCell;

/// `std::cell::UnsafeCell` with loom's closure-based access API, so the same code compiles
/// against both.
#[cfg(not(loom))]
#[derive(Debug)]
pub(crate) struct UnsafeCell<T>(std::cell::UnsafeCell<T>);

#[cfg(not(loom))]
impl<T> UnsafeCell<T> {
    /// Wraps a value.
    pub(crate) const fn new(value: T) -> Self {
        Self(std::cell::UnsafeCell::new(value))
    }

    /// Shared access through a raw pointer; the caller upholds the aliasing rules.
    #[inline(always)]
    pub(crate) fn with<R>(&self, f: impl FnOnce(*const T) -> R) -> R {
        f(self.0.get())
    }

    /// Exclusive access through a raw pointer; the caller upholds the aliasing rules.
    #[inline(always)]
    pub(crate) fn with_mut<R>(&self, f: impl FnOnce(*mut T) -> R) -> R {
        f(self.0.get())
    }
}

/// Aligns a value to its own cache line pair so that the producer's and the consumer's hot
/// fields do not false-share (128 bytes: adjacent-line prefetch on x86).
#[derive(Debug, Default)]
#[repr(align(128))]
pub(crate) struct Padded<T>(pub(crate) T);

impl<T> std::ops::Deref for Padded<T> {
    type Target = T;
    #[inline(always)]
    fn deref(&self) -> &T {
        &self.0
    }
}

/// A sequentially consistent fence when model checking with loom; nothing in normal builds.
///
/// Why: loom models `SeqCst` loads and stores as `AcqRel` (loom's README, "Unsupported
/// features"), so it explores store-then-load reorderings across two locations that the single
/// total order of `SeqCst` accesses forbids, and reports races the real code cannot have. The
/// data object relies on exactly that order (the writer publishes, then looks at the readers'
/// markers; a reader marks itself busy, then looks at the publication). Calling this between
/// the two `SeqCst` accesses makes loom model the guarantee the accesses already give in
/// normal builds, where it compiles to nothing (on x86 the `SeqCst` store is already a locked
/// instruction; on AArch64 `stlr`/`ldar` keep their order).
#[inline(always)]
pub(crate) fn seqcst_order_for_loom() {
    #[cfg(loom)]
    loom::sync::atomic::fence(Ordering::SeqCst);
}

/// Locks a mutex, ignoring poisoning: the data behind our locks (subscriber lists, reader
/// registration) stays consistent even if a holder panicked, and no realtime path locks.
pub(crate) fn lock<T>(m: &Mutex<T>) -> impl std::ops::DerefMut<Target = T> + '_ {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}
