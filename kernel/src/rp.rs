//! Resource partitions: kernel-memory quotas.
//!
//! Every kernel object (task, thread) and every page-table frame is charged to one
//! partition. A new partition's quota is carved out of its creator's free quota, so the
//! quotas of all partitions together never exceed what the kernel reserved at boot, and
//! exhausting one partition can never make an allocation in another fail.

use crate::state::Kernel;
use crate::table::{RpIdx, TaskIdx};
use abi::syscall::Error;

/// Amounts of the three kinds of kernel memory.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Amount {
    pub tasks: u64,
    pub threads: u64,
    pub pages: u64,
}

impl Amount {
    pub const fn tasks(n: u64) -> Self {
        Self {
            tasks: n,
            threads: 0,
            pages: 0,
        }
    }
    pub const fn threads(n: u64) -> Self {
        Self {
            tasks: 0,
            threads: n,
            pages: 0,
        }
    }
    pub const fn pages(n: u64) -> Self {
        Self {
            tasks: 0,
            threads: 0,
            pages: n,
        }
    }
    fn plus(self, o: Self) -> Self {
        Self {
            tasks: self.tasks + o.tasks,
            threads: self.threads + o.threads,
            pages: self.pages + o.pages,
        }
    }
    fn fits_in(self, o: Self) -> bool {
        self.tasks <= o.tasks && self.threads <= o.threads && self.pages <= o.pages
    }
    fn minus(self, o: Self) -> Self {
        Self {
            tasks: self.tasks - o.tasks,
            threads: self.threads - o.threads,
            pages: self.pages - o.pages,
        }
    }
}

#[derive(Clone, Copy, Debug)]
pub struct ResourcePartition {
    pub in_use: bool,
    /// The task slot that created it (may place children in it).
    pub owner: TaskIdx,
    pub quota: Amount,
    /// Charged by objects and page tables of this partition.
    pub used: Amount,
    /// Handed on to partitions created from this one.
    pub carved: Amount,
    /// Bit n: its threads may run on CPU n.
    pub cpus: u8,
}

impl ResourcePartition {
    pub const FREE: Self = Self {
        in_use: false,
        owner: TaskIdx::ROOT,
        quota: Amount::tasks(0),
        used: Amount::tasks(0),
        carved: Amount::tasks(0),
        cpus: 0,
    };

    pub fn new(owner: TaskIdx, quota: Amount) -> Self {
        Self {
            in_use: true,
            owner,
            quota,
            used: Amount::default(),
            carved: Amount::default(),
            cpus: u8::MAX,
        }
    }

    pub fn free(&self) -> Amount {
        self.quota.minus(self.used.plus(self.carved))
    }

    /// Charges `amount`, or fails with `QuotaExceeded` and changes nothing.
    pub fn charge(&mut self, amount: Amount) -> Result<(), Error> {
        if !amount.fits_in(self.free()) {
            return Err(Error::QuotaExceeded);
        }
        self.used = self.used.plus(amount);
        Ok(())
    }

    pub fn release(&mut self, amount: Amount) {
        debug_assert!(amount.fits_in(self.used), "release more than charged");
        self.used = self.used.minus(amount);
    }

    /// Moves `quota` of the free quota into a new partition owned by `owner` whose threads
    /// run on `cpus`, some of this one's.
    pub fn carve(&mut self, owner: TaskIdx, quota: Amount, cpus: u64) -> Result<Self, Error> {
        let cpus = u8::try_from(cpus)
            .ok()
            .filter(|&c| c != 0 && c & !self.cpus == 0);
        let cpus = cpus.ok_or(Error::InvalidArgument)?;
        if !quota.fits_in(self.free()) {
            return Err(Error::QuotaExceeded);
        }
        self.carved = self.carved.plus(quota);
        Ok(Self {
            cpus,
            ..Self::new(owner, quota)
        })
    }
}

impl Kernel {
    /// The resource partition named by user-visible number `id` (slot + 1; 0 = `task`'s).
    pub fn resource_partition(&self, task: TaskIdx, id: u64) -> Result<RpIdx, Error> {
        match id {
            0 => Ok(self.tasks[task].rp()),
            n => usize::try_from(n - 1)
                .ok()
                .and_then(|r| self.rps.slot(r))
                .filter(|&r| self.rps[r].in_use)
                .ok_or(Error::NoSuchObject),
        }
    }

    pub fn rp_create(&mut self, task: TaskIdx, quota: Amount, cpus: u64) -> Result<RpIdx, Error> {
        let slot = self.rps.find(|r| !r.in_use).ok_or(Error::OutOfResources)?;
        let own = self.tasks[task].rp();
        self.rps[slot] = self.rps[own].carve(task, quota, cpus)?;
        Ok(slot)
    }
}

#[cfg(test)]
#[path = "../host-tests/rp.rs"]
mod tests;
