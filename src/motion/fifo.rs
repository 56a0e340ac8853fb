//! A fixed-size FIFO of `Copy` items inline in its owner: no heap, no lock, so the servo
//! thread's interpolator can queue what it reports (auxiliary items) and what it takes ahead
//! of the segment queue (the pieces a stop may run along) without allocating.

/// At most `N` items, oldest first.
#[derive(Debug, Clone, Copy)]
pub struct Fifo<T: Copy, const N: usize> {
    slots: [Option<T>; N],
    head: usize,
    len: usize,
}

impl<T: Copy, const N: usize> Fifo<T, N> {
    /// Empty.
    pub const fn new() -> Self {
        Fifo {
            slots: [None; N],
            head: 0,
            len: 0,
        }
    }

    /// Number of items held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when it holds nothing.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// True when it holds `N` items.
    pub fn is_full(&self) -> bool {
        self.len == N
    }

    /// Appends `item`; false (and nothing changed) when full.
    pub fn push(&mut self, item: T) -> bool {
        if self.is_full() {
            return false;
        }
        self.slots[(self.head + self.len) % N] = Some(item);
        self.len += 1;
        true
    }

    /// Removes and returns the oldest item.
    pub fn pop(&mut self) -> Option<T> {
        if self.len == 0 {
            return None;
        }
        let it = self.slots[self.head].take();
        self.head = (self.head + 1) % N;
        self.len -= 1;
        it
    }

    /// The `i`-th oldest item, if held.
    pub fn get(&self, i: usize) -> Option<T> {
        if i < self.len {
            self.slots[(self.head + i) % N]
        } else {
            None
        }
    }

    /// Drops every item.
    pub fn clear(&mut self) {
        *self = Self::new();
    }
}

impl<T: Copy, const N: usize> Default for Fifo<T, N> {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::Fifo;

    /// In order across the wrap of the slots, refusing a push when full, `get` counted from
    /// the oldest.
    #[test]
    fn items_leave_in_order_across_the_wrap() {
        let mut f: Fifo<u32, 3> = Fifo::new();
        for round in 0..5u32 {
            assert!(f.push(round * 10) && f.push(round * 10 + 1) && f.push(round * 10 + 2));
            assert!(f.is_full() && !f.push(99));
            assert_eq!(f.get(1), Some(round * 10 + 1));
            assert_eq!(f.get(3), None);
            assert_eq!(f.pop(), Some(round * 10));
            assert!(f.push(round * 10 + 3));
            for k in 1..=3 {
                assert_eq!(f.pop(), Some(round * 10 + k));
            }
            assert!(f.is_empty() && f.pop().is_none());
        }
        f.push(7);
        f.clear();
        assert_eq!((f.len(), f.pop()), (0, None));
    }
}
