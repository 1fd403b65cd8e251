//! The kernel's objects and the operations on them: tasks, threads, resource partitions,
//! address-space changes, scheduling state and timeouts.
//!
//! All of it lives in fixed tables inside one [`Kernel`] value (no heap), and none of it
//! touches hardware directly: the entry glue (`arch::entry`) saves the interrupted thread's
//! registers into its [`Thread`], calls in here, and loads whichever thread
//! [`Kernel::choose`] names. That keeps every decision host-testable.

use crate::mem::PAGE_SIZE;
use crate::mem::paging::{AddressSpace, is_user_range};
use crate::rp::{Amount, ResourcePartition};
use crate::sched::{RunQueues, TIME_PARTITIONS};
use crate::task::Task;
use crate::thread::{EMPTY_CONTEXT, FpuState, NEVER, NIL, State, Thread};
use crate::timepart::TimeTable;
use abi::root::{PhysRegion, ROOT_INFO_MAX_REGIONS};
use abi::syscall::{
    Abilities, Error, MAP_MAX_PAGES, PageRights, TASK_NAME_MAX, USER_END, make_id, split_id,
};

/// Byte `index` of an I/O bitmap frame.
#[allow(unsafe_code)] // the bitmap is a raw frame
fn io_byte(frame: u64, index: usize) -> u8 {
    // SAFETY: `frame` is a bitmap frame owned by a task; index < 4096 by construction.
    unsafe { *((crate::mem::phys_to_virt(frame) + index as u64) as *const u8) }
}

pub const MAX_THREADS: usize = 256;
pub const MAX_TASKS: usize = 64;
pub const MAX_RPS: usize = 16;

/// User code and stack selectors (GDT layout, see `arch::gdt`), RPL 3.
pub const USER_CS: u64 = 0x23;
pub const USER_SS: u64 = 0x1b;
/// RFLAGS of user threads: IF and the reserved bit 1.
pub const USER_RFLAGS: u64 = 0x202;

/// Where a map takes its frames from.
#[derive(Clone, Copy, Debug)]
pub enum Source {
    /// Pages of the caller's address space.
    Virtual(u64),
    /// Physical memory handed to the root task.
    Physical(u64),
}

pub struct Kernel {
    pub threads: [Thread; MAX_THREADS],
    pub tasks: [Task; MAX_TASKS],
    pub rps: [ResourcePartition; MAX_RPS],
    pub run: RunQueues<MAX_THREADS>,
    /// The thread whose registers and FPU state are loaded (or were, before idling).
    pub current: Option<usize>,
    /// The active window's time partition (none until a schedule exists).
    pub active_partition: Option<u8>,
    /// Raw thread id of the root task's health monitor (0 = none).
    pub health_monitor: u64,
    /// Physical memory the root task may map.
    pub user_memory: [PhysRegion; ROOT_INFO_MAX_REGIONS],
    pub user_memory_count: usize,
    /// Earliest deadline of any blocked thread (maybe stale-early after a wake-up).
    pub next_deadline: u64,
    /// Set when `next_deadline` moved earlier and the timer must be reprogrammed.
    pub timer_dirty: bool,
    /// The running thread's FS/GS base changed and must be reloaded on exit.
    pub reload_bases: bool,
    /// Schedules of time windows.
    pub time: TimeTable,
    /// Absolute time of the next window boundary (`NEVER` without a schedule).
    pub next_boundary: u64,
    /// CPU time per time partition and time with nothing to run, in TSC ticks.
    pub cpu_ticks: [u64; TIME_PARTITIONS],
    pub idle_ticks: u64,
    /// Time partition of the thread that ran since `last_account` (None: idle).
    pub running_partition: Option<u8>,
    pub last_account: u64,
    /// Raw id of the task whose I/O bitmap is in the TSS (0: ports disabled).
    pub io_loaded: u64,
    /// Interrupt lines attached to threads.
    pub irqs: crate::irq::Irqs,
}

impl Default for Kernel {
    fn default() -> Self {
        Self::new()
    }
}

impl Kernel {
    pub const fn new() -> Self {
        Self {
            threads: [Thread::FREE; MAX_THREADS],
            tasks: [Task::FREE; MAX_TASKS],
            rps: [ResourcePartition {
                in_use: false,
                owner: 0,
                quota: Amount::tasks(0),
                used: Amount::tasks(0),
                carved: Amount::tasks(0),
            }; MAX_RPS],
            run: RunQueues::new(),
            current: None,
            active_partition: None,
            health_monitor: 0,
            user_memory: [PhysRegion { start: 0, pages: 0 }; ROOT_INFO_MAX_REGIONS],
            user_memory_count: 0,
            next_deadline: NEVER,
            timer_dirty: false,
            reload_bases: false,
            time: TimeTable::new(),
            next_boundary: NEVER,
            cpu_ticks: [0; TIME_PARTITIONS],
            idle_ticks: 0,
            running_partition: None,
            last_account: 0,
            io_loaded: 0,
            irqs: crate::irq::Irqs::new(),
        }
    }

    // ----- identifiers and rights -------------------------------------------------------

    pub fn thread_id(&self, t: usize) -> u64 {
        make_id(t, self.threads[t].generation)
    }

    pub fn task_id(&self, t: usize) -> u64 {
        make_id(t, self.tasks[t].generation)
    }

    pub fn thread(&self, id: u64) -> Result<usize, Error> {
        let (index, generation) = split_id(id).ok_or(Error::NoSuchObject)?;
        match self.threads.get(index) {
            Some(t) if !t.is_free() && t.generation == generation => Ok(index),
            _ => Err(Error::NoSuchObject),
        }
    }

    pub fn task(&self, id: u64) -> Result<usize, Error> {
        let (index, generation) = split_id(id).ok_or(Error::NoSuchObject)?;
        match self.tasks.get(index) {
            Some(t) if t.in_use && t.generation == generation => Ok(index),
            _ => Err(Error::NoSuchObject),
        }
    }

    /// True if `task` is `ancestor` or one of its descendants.
    pub fn is_within(&self, task: usize, ancestor: usize) -> bool {
        let mut at = Some(task);
        // The tree has at most MAX_TASKS levels.
        for _ in 0..MAX_TASKS {
            match at {
                Some(t) if t == ancestor => return true,
                Some(t) => at = self.tasks[t].parent,
                None => return false,
            }
        }
        false
    }

    /// The task named by `id` (0 = `caller`'s own), if the caller controls it.
    pub fn controlled_task(&self, caller: usize, id: u64) -> Result<usize, Error> {
        let task = if id == 0 { caller } else { self.task(id)? };
        if self.is_within(task, caller) {
            Ok(task)
        } else {
            Err(Error::NotPermitted)
        }
    }

    /// The thread named by `id` (0 = `caller_thread`), if the caller's task controls it.
    pub fn controlled_thread(&self, caller_thread: usize, id: u64) -> Result<usize, Error> {
        let thread = if id == 0 {
            caller_thread
        } else {
            self.thread(id)?
        };
        if self.is_within(self.threads[thread].task, self.threads[caller_thread].task) {
            Ok(thread)
        } else {
            Err(Error::NotPermitted)
        }
    }

    pub fn may_send(&self, from_task: usize, to_task: usize) -> bool {
        self.tasks[from_task].send_to & (1 << to_task) != 0
    }

    pub fn require(&self, task: usize, ability: Abilities) -> Result<(), Error> {
        if self.tasks[task].abilities.contains(ability) {
            Ok(())
        } else {
            Err(Error::AbilityDenied)
        }
    }

    // ----- scheduling state -------------------------------------------------------------

    /// Changes a thread's state and keeps the run queues consistent with it.
    pub fn set_state(&mut self, t: usize, state: State) {
        self.threads[t].state = state;
        self.requeue(t);
    }

    fn requeue(&mut self, t: usize) {
        let th = &self.threads[t];
        if th.is_runnable() {
            self.run.enqueue(t, th.priority, th.time_partition);
        } else {
            self.run.remove(t);
        }
    }

    /// Ends a blocking call of `t` with `result` in its `rax` and makes it ready.
    pub fn wake(&mut self, t: usize, result: Error) {
        let th = &mut self.threads[t];
        th.context.rax = result as u64;
        th.deadline = NEVER;
        th.fault = None;
        self.set_state(t, State::Ready);
    }

    /// Blocks `t` in `state` until `deadline` (absolute ns; [`NEVER`] for none).
    pub fn block(&mut self, t: usize, state: State, deadline: u64) {
        self.threads[t].deadline = deadline;
        if deadline < self.next_deadline {
            self.next_deadline = deadline;
            self.timer_dirty = true;
        }
        self.set_state(t, state);
    }

    /// The thread to run next.
    pub fn choose(&self) -> Option<usize> {
        self.run.choose(self.active_partition)
    }

    /// A timer event at `now`: time-outs and window boundaries.
    pub fn on_timer(&mut self, now: u64) {
        // The one-shot timer has fired: re-arm it even if it fired a little early (its
        // count is rounded down) and nothing is due yet, or the next event would be missed.
        self.timer_dirty = true;
        if now >= self.next_deadline {
            self.expire_timeouts(now);
        }
        if now >= self.next_boundary {
            self.update_window(now);
        }
    }

    /// Recomputes the active window (after a boundary or a schedule change).
    pub fn update_window(&mut self, now: u64) {
        let position = self.time.advance(now);
        self.active_partition = position.partition;
        self.next_boundary = position.next_boundary;
        self.timer_dirty = true;
    }

    /// When the timer must fire next.
    pub fn next_event(&self) -> u64 {
        self.next_deadline.min(self.next_boundary)
    }

    /// Charges the time since the last call (TSC `now`) to the partition that ran, or idle.
    pub fn account(&mut self, now: u64) {
        let delta = now.saturating_sub(self.last_account);
        self.last_account = now;
        match self.running_partition {
            Some(p) => self.cpu_ticks[p as usize] += delta,
            None => self.idle_ticks += delta,
        }
    }

    /// Times out every blocked thread whose deadline is at or before `now` and recomputes
    /// the next deadline. Bounded by the thread table.
    pub fn expire_timeouts(&mut self, now: u64) {
        let mut next = NEVER;
        for t in 0..MAX_THREADS {
            let deadline = self.threads[t].deadline;
            if deadline == NEVER {
                continue;
            }
            if deadline <= now {
                self.abort_wait(t, Error::TimedOut);
            } else {
                next = next.min(deadline);
            }
        }
        self.next_deadline = next;
        self.timer_dirty = true;
    }

    /// Ends whatever `t` waits for with `error` (timeout or peer gone).
    pub fn abort_wait(&mut self, t: usize, error: Error) {
        match self.threads[t].state {
            State::Sending { to, .. } => {
                self.unqueue_sender(to, t);
                self.wake(t, error);
            }
            State::WaitingReply { .. } | State::Receiving { .. } | State::WaitingNotify { .. } => {
                self.wake(t, error)
            }
            State::Sleeping => self.wake(t, Error::Ok),
            State::Free | State::Inactive | State::Ready => self.threads[t].deadline = NEVER,
        }
    }

    // ----- send queues (priority order, FIFO within a priority) -------------------------

    pub fn enqueue_sender(&mut self, receiver: usize, sender: usize) {
        let priority = self.threads[sender].priority;
        // Insert before the first queued sender of lower priority.
        let mut prev = NIL;
        let mut at = self.threads[receiver].senders;
        while at != NIL && self.threads[at as usize].priority >= priority {
            prev = at;
            at = self.threads[at as usize].next_sender;
        }
        self.threads[sender].next_sender = at;
        if prev == NIL {
            self.threads[receiver].senders = sender as u16;
        } else {
            self.threads[prev as usize].next_sender = sender as u16;
        }
    }

    pub fn unqueue_sender(&mut self, receiver: usize, sender: usize) {
        let mut prev = NIL;
        let mut at = self.threads[receiver].senders;
        while at != NIL {
            if at as usize == sender {
                let next = self.threads[sender].next_sender;
                if prev == NIL {
                    self.threads[receiver].senders = next;
                } else {
                    self.threads[prev as usize].next_sender = next;
                }
                self.threads[sender].next_sender = NIL;
                return;
            }
            prev = at;
            at = self.threads[at as usize].next_sender;
        }
    }

    /// The first queued sender to `receiver` (from `from` only, if given).
    pub fn first_sender(&self, receiver: usize, from: Option<usize>) -> Option<usize> {
        let mut at = self.threads[receiver].senders;
        while at != NIL {
            if from.is_none_or(|f| f == at as usize) {
                return Some(at as usize);
            }
            at = self.threads[at as usize].next_sender;
        }
        None
    }

    // ----- resource partitions ----------------------------------------------------------

    /// The resource partition named by user-visible number `id` (slot + 1; 0 = `task`'s).
    pub fn resource_partition(&self, task: usize, id: u64) -> Result<usize, Error> {
        match id {
            0 => Ok(self.tasks[task].rp),
            n => usize::try_from(n - 1)
                .ok()
                .filter(|&r| r < MAX_RPS && self.rps[r].in_use)
                .ok_or(Error::NoSuchObject),
        }
    }

    pub fn rp_create(&mut self, caller_task: usize, quota: Amount) -> Result<usize, Error> {
        let slot = self
            .rps
            .iter()
            .position(|r| !r.in_use)
            .ok_or(Error::OutOfResources)?;
        let own = self.tasks[caller_task].rp;
        self.rps[slot] = self.rps[own].carve(caller_task, quota)?;
        Ok(slot)
    }

    // ----- tasks ------------------------------------------------------------------------

    /// Creates a child task of `parent`. Checks abilities ⊆ parent's and MCP ≤ parent's.
    pub fn create_task(
        &mut self,
        parent: usize,
        abilities: Abilities,
        mcp: u8,
        rp: usize,
        name: &str,
    ) -> Result<usize, Error> {
        let p = &self.tasks[parent];
        if !p.abilities.contains(abilities) {
            return Err(Error::AbilityDenied);
        }
        if mcp > p.mcp {
            return Err(Error::McpExceeded);
        }
        if name.len() as u64 > TASK_NAME_MAX {
            return Err(Error::InvalidArgument);
        }
        if !self.rps[rp].in_use {
            return Err(Error::NoSuchObject);
        }
        let slot = self
            .tasks
            .iter()
            .position(|t| !t.in_use)
            .ok_or(Error::QuotaExceeded)?;
        let cost = Amount {
            tasks: 1,
            threads: 0,
            pages: 1,
        };
        self.rps[rp].charge(cost)?;
        let Ok(space) = AddressSpace::new() else {
            self.rps[rp].release(cost);
            return Err(Error::OutOfResources);
        };
        let generation = self.tasks[slot].generation;
        let mut task = Task {
            in_use: true,
            generation,
            parent: Some(parent),
            abilities,
            mcp,
            rp,
            space,
            // Itself and its parent; the parent may send to it.
            send_to: (1 << slot) | (1 << parent),
            pages_charged: 1,
            ..Task::FREE
        };
        task.name[..name.len()].copy_from_slice(name.as_bytes());
        task.name_len = name.len() as u8;
        self.tasks[slot] = task;
        self.tasks[parent].send_to |= 1 << slot;
        Ok(slot)
    }

    /// Destroys `task` and its whole subtree: threads, address spaces, send rights.
    pub fn destroy_task(&mut self, task: usize) {
        // Children first (bounded: each round removes one task).
        for _ in 0..MAX_TASKS {
            let Some(child) = (0..MAX_TASKS)
                .find(|&c| self.tasks[c].in_use && self.tasks[c].parent == Some(task))
            else {
                break;
            };
            self.destroy_task(child);
        }
        for t in 0..MAX_THREADS {
            if !self.threads[t].is_free() && self.threads[t].task == task {
                self.kill_thread(t);
            }
        }
        let rp = self.tasks[task].rp;
        let mut freed = self.tasks[task].space.destroy();
        for frame in self.tasks[task].io_bitmap {
            if frame != 0 {
                crate::mem::free_frame(frame);
                freed += 1;
            }
        }
        if self.io_loaded == self.task_id(task) {
            self.io_loaded = 0;
        }
        debug_assert_eq!(freed, self.tasks[task].pages_charged);
        self.rps[rp].release(Amount {
            tasks: 1,
            threads: 0,
            pages: self.tasks[task].pages_charged,
        });
        for other in self.tasks.iter_mut() {
            other.send_to &= !(1 << task);
        }
        let generation = self.tasks[task].generation.wrapping_add(1);
        self.tasks[task] = Task {
            generation,
            ..Task::FREE
        };
    }

    // ----- threads ----------------------------------------------------------------------

    /// A new inactive thread of `task` that will start at `entry` with `rsp` = `stack` and
    /// `rdi` = `arg`.
    pub fn create_thread(
        &mut self,
        task: usize,
        entry: u64,
        stack: u64,
        priority: u8,
        time_partition: u8,
        arg: u64,
    ) -> Result<usize, Error> {
        if priority > self.tasks[task].mcp {
            return Err(Error::McpExceeded);
        }
        if entry >= USER_END || stack > USER_END || time_partition as usize >= TIME_PARTITIONS {
            return Err(Error::InvalidArgument);
        }
        let slot = self
            .threads
            .iter()
            .position(|t| t.is_free())
            .ok_or(Error::QuotaExceeded)?;
        self.rps[self.tasks[task].rp].charge(Amount::threads(1))?;
        let generation = self.threads[slot].generation;
        self.threads[slot] = Thread {
            state: State::Inactive,
            generation,
            task,
            priority,
            time_partition,
            context: crate::arch::idt::TrapFrame {
                rip: entry,
                rsp: stack,
                rdi: arg,
                cs: USER_CS,
                ss: USER_SS,
                rflags: USER_RFLAGS,
                ..EMPTY_CONTEXT
            },
            fpu: FpuState::initial(),
            ..Thread::FREE
        };
        Ok(slot)
    }

    /// Destroys a thread: whoever waits on it gets `PeerGone`, its slot is freed and its
    /// quota returned.
    pub fn kill_thread(&mut self, t: usize) {
        if self.threads[t].is_free() {
            return;
        }
        // Leave any queue it is in.
        if let State::Sending { to, .. } = self.threads[t].state {
            self.unqueue_sender(to, t);
        }
        self.run.remove(t);
        self.release_irqs_of(t);
        let id = self.thread_id(t);
        // Everyone waiting for it: its senders, its callers, receivers waiting on it.
        for other in 0..MAX_THREADS {
            if other == t {
                continue;
            }
            let waits_on_t = match self.threads[other].state {
                State::Sending { to, .. } => to == t,
                State::WaitingReply { from } => from == t,
                _ => false,
            };
            if waits_on_t && self.threads[other].fault.is_some() {
                // Its handler is gone: nobody can resolve the fault.
                self.kill_thread(other);
                continue;
            }
            match self.threads[other].state {
                State::Sending { to, .. } if to == t => {
                    self.unqueue_sender(t, other);
                    self.wake(other, Error::PeerGone);
                }
                State::WaitingReply { from } if from == t => self.wake(other, Error::PeerGone),
                State::Receiving { from: Some(f) } if f == t => self.wake(other, Error::PeerGone),
                _ => {}
            }
        }
        if self.health_monitor == id {
            self.health_monitor = 0;
        }
        if self.current == Some(t) {
            self.current = None;
        }
        let rp = self.tasks[self.threads[t].task].rp;
        self.rps[rp].release(Amount::threads(1));
        let generation = self.threads[t].generation.wrapping_add(1);
        self.threads[t] = Thread {
            generation,
            ..Thread::FREE
        };
    }

    pub fn set_suspended(&mut self, t: usize, suspended: bool) {
        self.threads[t].suspended = suspended;
        self.requeue(t);
    }

    pub fn set_priority(&mut self, t: usize, priority: u8) -> Result<(), Error> {
        if priority > self.tasks[self.threads[t].task].mcp {
            return Err(Error::McpExceeded);
        }
        self.run.remove(t);
        self.threads[t].priority = priority;
        self.requeue(t);
        Ok(())
    }

    pub fn set_time_partition(&mut self, t: usize, partition: u8) -> Result<(), Error> {
        if partition as usize >= TIME_PARTITIONS {
            return Err(Error::InvalidArgument);
        }
        self.run.remove(t);
        self.threads[t].time_partition = partition;
        self.requeue(t);
        Ok(())
    }

    // ----- I/O ports --------------------------------------------------------------------

    /// True if `task` may use `port` (the root: every port but the kernel's).
    pub fn holds_port(&self, task: usize, port: u16) -> bool {
        if task == 0 {
            return !abi::syscall::KERNEL_PORTS
                .iter()
                .any(|&(lo, hi)| (lo..=hi).contains(&port));
        }
        let frame = self.tasks[task].io_bitmap[port as usize / 32768];
        frame != 0 && {
            let bit = port as usize % 32768;
            io_byte(frame, bit / 8) & (1 << (bit % 8)) == 0
        }
    }

    /// Grants ports `first..first + count` of `caller` to the descendant `target`.
    #[allow(unsafe_code)] // the bitmap is a raw frame
    pub fn io_grant(
        &mut self,
        caller: usize,
        target: usize,
        first: u64,
        count: u64,
    ) -> Result<(), Error> {
        if count == 0 || first.checked_add(count).is_none_or(|end| end > 0x1_0000) {
            return Err(Error::InvalidArgument);
        }
        if target == caller || !self.is_within(target, caller) {
            return Err(Error::NotPermitted);
        }
        let ports = first as u16..=(first + count - 1) as u16;
        if !ports.clone().all(|p| self.holds_port(caller, p)) {
            return Err(Error::NotPermitted);
        }
        if self.tasks[target].io_bitmap[0] == 0 {
            self.rps[self.tasks[target].rp].charge(Amount::pages(2))?;
            let frames = [
                crate::mem::alloc_zeroed_frame(),
                crate::mem::alloc_zeroed_frame(),
            ];
            let [Some(a), Some(b)] = frames else {
                // Cannot happen within the reserved pool; undo and refuse.
                frames
                    .into_iter()
                    .flatten()
                    .for_each(crate::mem::free_frame);
                self.rps[self.tasks[target].rp].release(Amount::pages(2));
                return Err(Error::OutOfResources);
            };
            for frame in [a, b] {
                // SAFETY: a fresh frame, direct-mapped, 4 KiB: "every port denied".
                unsafe {
                    core::ptr::write_bytes(
                        crate::mem::phys_to_virt(frame) as *mut u8,
                        0xff,
                        PAGE_SIZE as usize,
                    )
                };
            }
            self.tasks[target].io_bitmap = [a, b];
            self.tasks[target].pages_charged += 2;
        }
        for port in ports {
            let frame = self.tasks[target].io_bitmap[port as usize / 32768];
            let bit = port as usize % 32768;
            let byte = crate::mem::phys_to_virt(frame) + (bit / 8) as u64;
            // SAFETY: inside the task's bitmap frame (bit / 8 < 4096), direct-mapped.
            unsafe { *(byte as *mut u8) &= !(1 << (bit % 8)) };
        }
        if self.io_loaded == self.task_id(target) {
            self.io_loaded = 0;
        }
        Ok(())
    }

    // ----- memory -----------------------------------------------------------------------

    /// True if the physical range was handed to the root task at boot.
    pub fn is_user_memory(&self, start: u64, pages: u64) -> bool {
        abi::root::regions_contain(&self.user_memory[..self.user_memory_count], start, pages)
    }

    /// Maps `pages` pages from `source` into `target` at `destination`. All-or-nothing:
    /// everything is checked and the page tables are charged before anything changes.
    pub fn map(
        &mut self,
        caller: usize,
        target: usize,
        source: Source,
        destination: u64,
        pages: u64,
        rights: PageRights,
    ) -> Result<(), Error> {
        if pages == 0 || pages > MAP_MAX_PAGES || !is_user_range(destination, pages) {
            return Err(Error::InvalidArgument);
        }
        let frame_of = |k: &Self, i: u64| -> Result<u64, Error> {
            match source {
                Source::Virtual(base) => {
                    match k.tasks[caller].space.translate(base + i * PAGE_SIZE) {
                        Some((frame, have)) if have.contains(rights) => Ok(frame),
                        _ => Err(Error::BadAddress),
                    }
                }
                Source::Physical(base) => Ok(base + i * PAGE_SIZE),
            }
        };
        match source {
            Source::Virtual(base) if !is_user_range(base, pages) => {
                return Err(Error::InvalidArgument);
            }
            Source::Physical(base) if base % PAGE_SIZE != 0 => {
                return Err(Error::InvalidArgument);
            }
            Source::Physical(base) if !self.is_user_memory(base, pages) => {
                return Err(Error::BadAddress);
            }
            _ => {}
        }
        let space = self.tasks[target].space;
        for i in 0..pages {
            frame_of(self, i)?;
            if space.translate(destination + i * PAGE_SIZE).is_some() {
                return Err(Error::AlreadyMapped);
            }
        }
        self.charge_tables(target, destination, pages)?;
        for i in 0..pages {
            let frame = frame_of(self, i)?;
            self.tasks[target]
                .space
                .map(destination + i * PAGE_SIZE, frame, rights)
                .expect("checked and charged");
        }
        Ok(())
    }

    /// Charges the page tables a map of `pages` at `at` in `task` will need.
    pub fn charge_tables(&mut self, task: usize, at: u64, pages: u64) -> Result<(), Error> {
        let needed = self.tasks[task].space.tables_needed(at, pages);
        if needed > crate::mem::free_frames() {
            // Cannot happen while quotas stay within the reserved pool; refuse anyway.
            return Err(Error::OutOfResources);
        }
        self.rps[self.tasks[task].rp].charge(Amount::pages(needed))?;
        self.tasks[task].pages_charged += needed;
        Ok(())
    }

    pub fn unmap(&mut self, target: usize, address: u64, pages: u64) -> Result<(), Error> {
        if pages == 0 || pages > MAP_MAX_PAGES || !is_user_range(address, pages) {
            return Err(Error::InvalidArgument);
        }
        for i in 0..pages {
            self.tasks[target].space.unmap(address + i * PAGE_SIZE);
        }
        Ok(())
    }

    pub fn protect(
        &mut self,
        target: usize,
        address: u64,
        pages: u64,
        rights: PageRights,
    ) -> Result<(), Error> {
        if pages == 0 || pages > MAP_MAX_PAGES || !is_user_range(address, pages) {
            return Err(Error::InvalidArgument);
        }
        let space = &mut self.tasks[target].space;
        for i in 0..pages {
            match space.translate(address + i * PAGE_SIZE) {
                Some((_, have)) if have.contains(rights) => {}
                _ => return Err(Error::BadAddress),
            }
        }
        for i in 0..pages {
            space.set_rights(address + i * PAGE_SIZE, rights);
        }
        Ok(())
    }
}
