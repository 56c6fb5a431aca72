//! Helpers for the end-to-end tests: a counting global allocator.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

thread_local! {
    // `const` and destructor-free: reading it from inside the allocator cannot allocate.
    static THIS_THREAD: Cell<usize> = const { Cell::new(0) };
}

/// Global allocator that counts allocations (and reallocations) made while armed.
///
/// Install it in a test binary with `#[global_allocator]`, then measure a closure with
/// [`CountingAllocator::count`].
#[derive(Debug)]
pub struct CountingAllocator {
    allocations: AtomicUsize,
}

impl CountingAllocator {
    /// A fresh counter.
    pub const fn new() -> Self {
        Self {
            allocations: AtomicUsize::new(0),
        }
    }

    /// Runs `f` and returns how many allocations the calling thread made meanwhile. Other
    /// threads are not counted: the test harness's main thread allocates when it reports a
    /// test running for over 60 s, which a loaded 2-core machine reaches.
    pub fn count<R>(&self, f: impl FnOnce() -> R) -> (usize, R) {
        let before = THIS_THREAD.with(Cell::get);
        let r = f();
        (THIS_THREAD.with(Cell::get) - before, r)
    }
}

impl Default for CountingAllocator {
    fn default() -> Self {
        Self::new()
    }
}

// SAFETY: forwards every call unchanged to the system allocator; only counts.
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        self.note();
        // SAFETY: same contract as ours.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as ours.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        self.note();
        // SAFETY: same contract as ours.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        self.note();
        // SAFETY: same contract as ours.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

impl CountingAllocator {
    fn note(&self) {
        self.allocations.fetch_add(1, Ordering::Relaxed);
        // A thread being torn down may no longer reach its thread-locals; it is not counted.
        let _ = THIS_THREAD.try_with(|c| c.set(c.get() + 1));
    }

    /// Allocations counted in every thread since the process started (for probes that read the count at two
    /// points of a long-running loop).
    pub fn total(&self) -> usize {
        self.allocations.load(Ordering::SeqCst)
    }
}
