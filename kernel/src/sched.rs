//! Ready queues: fixed priorities 0..=255, FIFO within a priority, O(1) choice.
//!
//! One set of queues per CPU and time partition: a thread runs on one CPU. The eligible
//! threads of a CPU at any instant are its threads of time partition 0 (background) plus
//! those of its active window's partition, if any; the highest priority wins, and on equal
//! priority the active partition's thread wins over the background. Queues are intrusive doubly-linked lists over thread slot indices, with a
//! 256-bit bitmap per partition for the non-empty priorities, so enqueue, dequeue and
//! choice are constant time. The running thread stays at the head of its queue: a
//! preempted thread resumes before its peers, and [`RunQueues::rotate`] implements yield.

pub const PRIORITIES: usize = 256;
pub const TIME_PARTITIONS: usize = abi::syscall::TIME_PARTITIONS as usize;
pub const CPUS: usize = abi::machine::MAX_CPUS;
const NIL: u16 = u16::MAX;

#[derive(Clone, Copy)]
struct Queue {
    head: u16,
    tail: u16,
}

const EMPTY: Queue = Queue {
    head: NIL,
    tail: NIL,
};

struct Partition {
    queues: [Queue; PRIORITIES],
    bitmap: [u64; PRIORITIES / 64],
}

pub struct RunQueues<const THREADS: usize> {
    partitions: [[Partition; TIME_PARTITIONS]; CPUS],
    next: [u16; THREADS],
    prev: [u16; THREADS],
    /// Where each queued thread is; `None` when not queued.
    place: [Option<Place>; THREADS],
}

/// A queued thread's queue: its priority, time partition and CPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Place {
    pub priority: u8,
    pub partition: u8,
    pub cpu: u8,
}

impl<const THREADS: usize> Default for RunQueues<THREADS> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const THREADS: usize> RunQueues<THREADS> {
    pub const fn new() -> Self {
        assert!(THREADS < NIL as usize);
        Self {
            partitions: [const {
                [const {
                    Partition {
                        queues: [EMPTY; PRIORITIES],
                        bitmap: [0; PRIORITIES / 64],
                    }
                }; TIME_PARTITIONS]
            }; CPUS],
            next: [NIL; THREADS],
            prev: [NIL; THREADS],
            place: [None; THREADS],
        }
    }

    pub fn is_queued(&self, thread: usize) -> bool {
        self.place[thread].is_some()
    }

    /// Appends `thread` to the tail of its queue (no-op if already queued).
    pub fn enqueue(&mut self, thread: usize, place: Place) {
        if self.is_queued(thread) {
            return;
        }
        let Place {
            priority,
            partition,
            cpu,
        } = place;
        let p = &mut self.partitions[cpu as usize][partition as usize];
        let q = &mut p.queues[priority as usize];
        self.prev[thread] = q.tail;
        self.next[thread] = NIL;
        if q.tail == NIL {
            q.head = thread as u16;
        } else {
            self.next[q.tail as usize] = thread as u16;
        }
        q.tail = thread as u16;
        p.bitmap[priority as usize / 64] |= 1 << (priority % 64);
        self.place[thread] = Some(place);
    }

    /// Takes `thread` out of its queue (no-op if not queued).
    pub fn remove(&mut self, thread: usize) {
        let Some(Place {
            priority,
            partition,
            cpu,
        }) = self.place[thread].take()
        else {
            return;
        };
        let p = &mut self.partitions[cpu as usize][partition as usize];
        let q = &mut p.queues[priority as usize];
        let (prev, next) = (self.prev[thread], self.next[thread]);
        if prev == NIL {
            q.head = next;
        } else {
            self.next[prev as usize] = next;
        }
        if next == NIL {
            q.tail = prev;
        } else {
            self.prev[next as usize] = prev;
        }
        if q.head == NIL {
            p.bitmap[priority as usize / 64] &= !(1 << (priority % 64));
        }
    }

    /// Moves a queued thread to the tail of its queue (yield).
    pub fn rotate(&mut self, thread: usize) {
        if let Some(place) = self.place[thread] {
            self.remove(thread);
            self.enqueue(thread, place);
        }
    }

    fn highest(&self, cpu: usize, partition: usize) -> Option<(u8, usize)> {
        let p = &self.partitions[cpu][partition];
        for word in (0..p.bitmap.len()).rev() {
            if p.bitmap[word] != 0 {
                let priority = word * 64 + 63 - p.bitmap[word].leading_zeros() as usize;
                return Some((priority as u8, p.queues[priority].head as usize));
            }
        }
        None
    }

    /// The thread to run on `cpu`: the highest priority among its threads of time
    /// partition 0 and `active`.
    pub fn choose(&self, cpu: usize, active: Option<u8>) -> Option<usize> {
        let background = self.highest(cpu, 0);
        let foreground = active
            .filter(|&a| a != 0)
            .and_then(|a| self.highest(cpu, a as usize));
        match (foreground, background) {
            (Some((fp, ft)), Some((bp, _))) if fp >= bp => Some(ft),
            (_, Some((_, bt))) => Some(bt),
            (Some((_, ft)), None) => Some(ft),
            (None, None) => None,
        }
    }
}

#[cfg(test)]
#[path = "../host-tests/sched.rs"]
mod tests;
