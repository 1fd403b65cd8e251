//! A resource's event queue: each queued event's destination with the values it carries
//! (the destination's WITH inputs as they were sampled when it was sent), first in, first
//! out. Two rings, one of events and one of their values one event's after the other's,
//! so queueing and delivering an event allocate nothing once both have grown, and cost a
//! masked index each (an event is queued and delivered once per delivery: this is the
//! resource's innermost loop).

use crate::value::Value;
use alloc::vec::Vec;

/// `(instance, port index)`.
pub(crate) type End = (usize, usize);

/// A first-in first-out ring that doubles when full. A slot outside the queue owns nothing
/// (it holds `T::default()`, a copy of an item that was `Copy`, or what the caller of
/// [`Ring::pop_in_place`] left there), so a push overwrites it without a drop to run.
struct Ring<T> {
    /// A power of two long, or empty.
    slots: Vec<T>,
    head: usize,
    len: usize,
}

impl<T: Default> Ring<T> {
    const fn new() -> Self {
        Ring {
            slots: Vec::new(),
            head: 0,
            len: 0,
        }
    }

    /// Queues `item`; returns it in its slot.
    #[inline(always)]
    fn push(&mut self, item: T) -> &mut T {
        if self.len == self.slots.len() {
            self.grow();
        }
        let at = (self.head + self.len) & (self.slots.len() - 1);
        self.len += 1;
        let slot = &mut self.slots[at];
        // The slot owns nothing (see `Ring`): forgetting what it holds leaks nothing.
        core::mem::forget(core::mem::replace(slot, item));
        slot
    }

    #[inline(always)]
    fn pop(&mut self) -> Option<T> {
        if self.len == 0 {
            return None;
        }
        let item = core::mem::take(&mut self.slots[self.head]);
        self.head = (self.head + 1) & (self.slots.len() - 1);
        self.len -= 1;
        Some(item)
    }

    /// [`Ring::pop`] of an item that owns nothing: the slot is left as it is.
    #[inline(always)]
    fn pop_copy(&mut self) -> Option<T>
    where
        T: Copy,
    {
        if self.len == 0 {
            return None;
        }
        let item = self.slots[self.head];
        self.head = (self.head + 1) & (self.slots.len() - 1);
        self.len -= 1;
        Some(item)
    }

    /// Hands the next item to `take`, which must leave in its place something that owns
    /// nothing (see [`Ring`]); false when the ring is empty.
    #[inline(always)]
    fn pop_in_place(&mut self, take: impl FnOnce(&mut T)) -> bool {
        if self.len == 0 {
            return false;
        }
        take(&mut self.slots[self.head]);
        self.head = (self.head + 1) & (self.slots.len() - 1);
        self.len -= 1;
        true
    }

    /// Twice the slots (16 at first), the queued items first, in order.
    #[cold]
    #[inline(never)]
    fn grow(&mut self) {
        let capacity = (self.slots.len() * 2).max(16);
        let mut slots = Vec::with_capacity(capacity);
        while let Some(item) = self.pop() {
            slots.push(item);
        }
        self.len = slots.len();
        self.head = 0;
        slots.resize_with(capacity, T::default);
        self.slots = slots;
    }

    fn clear(&mut self) {
        while self.pop().is_some() {}
        self.head = 0;
    }
}

/// The event queue.
pub(crate) struct EventQueue {
    /// Each event's destination and how many values it carries.
    events: Ring<(End, usize)>,
    /// The values: `(input index, value)`.
    values: Ring<(usize, Value)>,
}

impl Default for EventQueue {
    fn default() -> Self {
        EventQueue {
            events: Ring::new(),
            values: Ring::new(),
        }
    }
}

impl EventQueue {
    pub(crate) fn len(&self) -> usize {
        self.events.len
    }

    pub(crate) fn clear(&mut self) {
        self.events.clear();
        self.values.clear();
    }

    /// Queues an event to `to` carrying `values`.
    pub(crate) fn push(&mut self, to: End, values: impl Iterator<Item = (usize, Value)>) {
        let mut n = 0;
        for value in values {
            self.values.push(value);
            n += 1;
        }
        self.events.push((to, n));
    }

    /// Queues one value of the event the next [`EventQueue::push_event`] queues.
    #[inline(always)]
    pub(crate) fn push_value(&mut self, input: usize, value: Value) -> &mut Value {
        &mut self.values.push((input, value)).1
    }

    /// Queues an event to `to` that carries the `carried` values pushed just before.
    #[inline(always)]
    pub(crate) fn push_event(&mut self, to: End, carried: usize) {
        self.events.push((to, carried));
    }

    /// The next event's destination and how many values it carries, which the caller
    /// takes with [`EventQueue::pop_value`] before the next `pop` (a counted loop: no
    /// iterator to build and drop per event).
    #[inline(always)]
    pub(crate) fn pop(&mut self) -> Option<(End, usize)> {
        self.events.pop_copy()
    }

    /// The next value of the event [`EventQueue::pop`] returned (input index, value).
    #[inline(always)]
    pub(crate) fn pop_value(&mut self) -> Option<(usize, Value)> {
        self.values.pop()
    }

    /// Delivers the next value of the event [`EventQueue::pop`] returned into `inputs`
    /// (an index out of `inputs` is dropped): a swap, the input's old value put in the
    /// queue's slot and dropped there only if it owns something.
    #[inline(always)]
    pub(crate) fn deliver_value(&mut self, inputs: &mut [Value]) {
        self.values.pop_in_place(|(input, value)| {
            if let Some(target) = inputs.get_mut(*input) {
                core::mem::swap(target, value);
            }
            if !value.is_scalar() {
                *value = Value::default();
            }
        });
    }

    /// Drops the events to instance `i` with their values.
    pub(crate) fn forget(&mut self, i: usize) {
        let mut kept = EventQueue::default();
        while let Some((to, n)) = self.pop() {
            let values: Vec<_> = (0..n).filter_map(|_| self.pop_value()).collect();
            if to.0 != i {
                kept.push(to, values.into_iter());
            }
        }
        *self = kept;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_come_out_in_order_with_their_values_across_growth_and_wrap_around() {
        let mut q = EventQueue::default();
        let mut next_in = 0usize;
        let mut next_out = 0usize;
        // Push three, pop two, many times: the rings wrap around and grow.
        for _ in 0..100 {
            for _ in 0..3 {
                let values = (0..next_in % 3).map(|k| (k, Value::UInt((next_in + k) as u64)));
                q.push((next_in, 1), values);
                next_in += 1;
            }
            for _ in 0..2 {
                let ((to, _), n) = q.pop().unwrap();
                assert_eq!((to, n), (next_out, next_out % 3));
                for k in 0..n {
                    let expected = (k, Value::UInt((next_out + k) as u64));
                    assert_eq!(q.pop_value(), Some(expected));
                }
                next_out += 1;
            }
        }
        assert_eq!(q.len(), 100);
        q.forget(next_out);
        assert_eq!(q.len(), 99);
        assert_eq!(q.pop().unwrap().0, (next_out + 1, 1));
        q.clear();
        assert_eq!((q.len(), q.pop(), q.pop_value()), (0, None, None));
    }

    #[test]
    fn strings_are_not_leaked_or_dropped_twice() {
        let mut q = EventQueue::default();
        for i in 0..40 {
            q.push(
                (i, 0),
                [(0, Value::String(alloc::format!("{i}")))].into_iter(),
            );
        }
        for i in 0..20 {
            q.pop();
            assert_eq!(
                q.pop_value(),
                Some((0, Value::String(alloc::format!("{i}"))))
            );
        }
        q.clear();
    }
}
