//! The guest's scheduling policy: which of three priorities each Linux process's thread
//! runs at (on each of the guest's CPUs), and on which CPU a new thread goes ([`place`]), so
//! that processes that wait (for a pipe, the console, a child, a timer, a port)
//! run as soon as they may, while processes that keep the CPU share it in turn and are
//! never starved for ever. Pure decisions over pids and times; the partition program
//! (`main.rs`) reports what happens to the processes' threads ([`Scheduler::received`],
//! [`Scheduler::replied`], [`Scheduler::stopped`], [`Scheduler::forget`]), asks for the
//! decisions due ([`Scheduler::decide`]) and sets the priorities [`Scheduler::level`]
//! names. It never calls the kernel and never looks at what a process does beyond when it
//! runs, waits and is answered.
//!
//! **The mechanism it works with.** The kernel runs the highest-priority ready thread, FIFO
//! within a priority (a preempted thread resumes first), and a thread whose exception
//! message the guest answers joins the *tail* of its priority's queue. Each system call
//! and page fault of a process is such a message. So with every process at one priority,
//! a process that makes a call queues behind a process spinning in user code and makes one
//! call per time slice: a command of 100 calls beside `while :; do :; done` took a second.
//!
//! **The policy** (a multi-level feedback queue, as in the schedulers of Solaris, the BSDs
//! and Linux before CFS), three levels below the guest's own thread:
//!
//! - [`Level::Interactive`] (the processes' highest priority): processes that waited
//!   recently, and new ones. A call they make puts them behind other interactive ones
//!   only, which soon wait themselves.
//! - [`Level::Turn`] (one below): the one CPU-bound process whose turn it is. Alone at its
//!   priority, it keeps the CPU across its own calls and faults for its whole slice.
//! - [`Level::Queued`] (two below): the other CPU-bound processes, waiting for their turn.
//!
//! Each process has a CPU *debt*: the time it ran (as the process the guest's model says
//! holds the CPU, or whose message the guest served) less the time it waited, between 0
//! and one [`SLICE_NS`]. An interactive process whose debt reaches a slice has run a whole
//! slice more than it waited: it becomes CPU-bound and joins the back of the turn order. A
//! process that waits (its reply deferred: a pipe, the console, `wait4`, a sleep, `poll`,
//! a port; a vfork parent; or stopped) is interactive when it is woken, a CPU-bound one
//! with a debt of a slice less the time it waited: one that waited a slice or longer
//! starts afresh, one that waited a moment (a busy pipe's writer) soon is CPU-bound again,
//! so waiting briefly buys no more CPU than the wait was long. The turn passes after its
//! holder has run a slice to the next CPU-bound process in turn order (round robin): the
//! CPU-bound processes share equally what the interactive ones leave.
//!
//! **Aging.** Interactive processes could keep the CPU busy between them for ever (a pipe
//! whose two ends wake each other, a stream of connections each served by a new child).
//! A CPU-bound process that has not run for [`STARVATION_NS`] is made interactive with no
//! debt: it runs a slice at the top level, beside them, and is CPU-bound again. So each
//! CPU-bound process gets a slice in every `STARVATION_NS` plus the slices of those aged
//! with it. (Aging only the turn holder gave n of them one slice each in n such periods:
//! busybox httpd's short-lived children, CPU-bound under TCG's costs, then waited to run
//! their `_exit` for longer than connections came, until the task quota refused a `fork`.)
//!
//! **Why three priorities and not two.** With the CPU-bound processes at one priority,
//! the kernel's FIFO would put one that makes a call behind the others: the bug above,
//! one level down. The guest decides whose turn it is, and the holder is alone at its
//! priority.
//!
//! **Why here, and why this policy.** The kernel offers fixed priorities, FIFO within one,
//! and `thread_set` of a priority below a task's MCP; which Linux process deserves the CPU
//! is the guest's business, as the partition's own (the processes stay below the guest's
//! MCP whatever the policy does). A fair-share scheduler (Linux's CFS) was the other
//! candidate: it would have to keep exactly one process above all others and move that
//! mark at every decision, and a woken process would wait for its virtual time to come.
//! The feedback queue lets the kernel's FIFO run the interactive processes without the
//! guest choosing among them, reacts to a wake-up before the woken thread runs, and costs
//! nothing for a call answered at once. Its known weakness: processes that wake each
//! other often (a pipeline) count as interactive however much CPU they use between them,
//! so beside them the CPU-bound ones get only what aging gives them.
//!
//! **The model of who runs.** The process whose message arrives is the one that ran since
//! the guest last looked (the guest's thread is above all of them, so it sees every
//! message at once); with no message (a time-out, console input), the model's choice ran:
//! the first runnable interactive process in the kernel's FIFO order (the order of the
//! guest's answers), else the turn holder. When another partition woke the guest (a port's
//! doorbell: the NIC partition's frames), that partition had the CPU at least in part:
//! the model's choice is charged only if it has made no call for [`STARVATION_NS`]
//! ([`Scheduler::outside`]). A process is runnable from its answer to its
//! next message; one still unanswered when the guest next looks waits. Times are the
//! guest's clock: the time a process held the CPU includes other partitions' windows and
//! the guest's work for it, so a slice is one of wall-clock time while the process was
//! the one to run.
//!
//! **Several CPUs.** A guest bound to several CPUs has its processes' threads on each
//! (placed by [`place`] from the process table, [`crate::system`]; this module only learns
//! where each runs: [`Scheduler::set_cpu`]), and the kernel schedules each CPU's threads
//! by their priorities there. So the policy is per CPU: each CPU has its own model of who
//! runs, its own turn holder and turn order among the CPU-bound threads placed on it, its
//! own aging and slice ends; two CPU-bound processes on two CPUs each hold their CPU's
//! turn and both run all the time. What happens on one CPU is charged there: between two
//! looks the sender of the message ran on its CPU, and on every other CPU the model's
//! choice there ran (one CPU's messages say nothing about another's spinner). The guest's
//! own thread follows its callers (`main.rs`): it serves each message on its sender's CPU,
//! in the time charged to the sender, as on one CPU; the decisions are the same
//! as before for each CPU, made in a pass per CPU when a decision is remade. A one-CPU
//! guest is the policy above unchanged.
//!
//! **Cost.** A message that changes nothing but the sender's debt (a call answered at
//! once) costs two lookups in the table and a comparison; the decisions are remade only
//! when a process waits, is woken, starts, ends or uses up its slice, or a decision is due.

use crate::system::MAX_PROCESSES;

/// How long a process runs before another that may run gets the CPU (Linux's default
/// scheduler gives a few milliseconds).
pub const SLICE_NS: u64 = 10_000_000;
/// How long the CPU-bound process whose turn it is may go without the CPU while
/// interactive processes keep it busy, before it runs a slice beside them.
pub const STARVATION_NS: u64 = 10 * SLICE_NS;
/// Most CPUs a guest may have: a resource partition's CPU mask has 8 bits (CPU 0..7).
pub const MAX_CPUS: usize = 8;

/// The runnable threads (running, or ready: not waiting in a call, not stopped) on each
/// CPU, by CPU number: what [`place`] balances.
pub type Load = [u16; MAX_CPUS];

/// The CPU of `allowed` (bit n: CPU n) with the fewest runnable threads in `load`; of
/// equals, `prefer` (the creator's CPU for a new thread, its own for a woken one), else the
/// lowest. An empty `allowed` (no CPU of the guest) keeps `prefer`.
pub fn place(allowed: u64, prefer: u32, load: &Load) -> u32 {
    (0..MAX_CPUS as u32)
        .filter(|&cpu| allowed >> cpu & 1 != 0)
        .min_by_key(|&cpu| (load[cpu as usize], cpu != prefer, cpu))
        .unwrap_or(prefer)
}

/// A process's scheduling level; each is one priority below the one before.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    /// Processes that waited recently, and new ones: the processes' highest priority.
    Interactive,
    /// The CPU-bound process whose turn it is.
    Turn,
    /// The other CPU-bound processes.
    Queued,
}

impl Level {
    /// How many priorities below the processes' highest the level is.
    pub const fn below_top(self) -> u8 {
        match self {
            Level::Interactive => 0,
            Level::Turn => 1,
            Level::Queued => 2,
        }
    }
}

#[derive(Clone, Copy, Debug)]
struct Entry {
    pid: u32,
    /// The CPU its thread runs on (its turn and its place in the model are that CPU's).
    cpu: u8,
    /// Placed ([`Scheduler::set_cpu`]) before its first answer: it holds only its CPU until
    /// then, as if it were not in the table (a new thread joins at its first answer).
    fresh: bool,
    /// Ran a whole slice more than it waited: it runs in turns.
    cpu_bound: bool,
    /// Its message was received and is not answered yet.
    in_call: bool,
    /// Stopped by a signal (its thread suspended).
    stopped: bool,
    /// Since when it waits, once the guest saw it wait (unanswered, or stopped).
    waiting_since: Option<u64>,
    /// It waited and was answered (or continued) since the guest last looked: it is
    /// woken when the guest looks next.
    woken: bool,
    /// Interactive: its debt (ns, at most a slice). CPU-bound: the time it ran in its
    /// current turn.
    used: u64,
    /// Interactive: when it joined the tail of the kernel's queue (the model of the
    /// kernel's FIFO order). CPU-bound: its place in the turn order.
    order: u64,
    /// When it last ran or got the turn (for aging).
    since: u64,
    /// When its last message was answered (as of the guest's last look).
    answered: u64,
}

impl Entry {
    fn runnable(&self) -> bool {
        !self.in_call && !self.stopped && !self.fresh
    }

    /// Its debt has reached what ends its slice.
    fn spent(&self) -> bool {
        self.used >= SLICE_NS
    }
}

/// What [`Scheduler::view`] sees of one CPU.
#[derive(Clone, Copy, Debug, Default)]
struct View {
    /// The first runnable interactive process in queue order: its slot and order.
    first_interactive: Option<(usize, u64)>,
    /// The first runnable CPU-bound process in turn order.
    first_bound: Option<(usize, u64)>,
    runnable: usize,
    cpu_bound: usize,
}

/// The scheduling state of the guest's processes.
#[derive(Clone, Debug)]
pub struct Scheduler {
    entries: [Option<Entry>; MAX_PROCESSES],
    /// The entries at or past this index have never been used: the passes over the table
    /// stop here (a guest with two processes looks at two).
    reached: usize,
    /// The guest's CPUs (bit n: CPU n).
    cpus: u64,
    /// The next `order`: every join of a queue's tail takes one.
    next_order: u64,
    /// When the guest last looked ([`Scheduler::decide`]).
    last: u64,
    /// The process whose message arrived since then.
    sender: Option<u32>,
    /// Since then another partition rang (frames came): the time is nobody's here.
    outside: bool,
    /// The process the model said holds each CPU when the guest last looked.
    head: [Option<u32>; MAX_CPUS],
    /// The CPU-bound process whose turn it is on each CPU (as of the last full decision).
    turn: [Option<u32>; MAX_CPUS],
    /// Something happened that the last decision did not see.
    dirty: bool,
    /// When the next decision is due (the last decision's answer).
    due: Option<u64>,
    /// Counts the decisions that may have changed a level.
    generation: u64,
    /// More than one interactive process was runnable on the CPU at the last decision: an
    /// answer to one may change which of them runs.
    contended: [bool; MAX_CPUS],
}

impl Scheduler {
    /// No processes yet, one CPU (CPU 0); the clock reads `now`.
    pub fn new(now: u64) -> Self {
        Self::with_cpus(now, 1)
    }

    /// No processes yet on the guest's CPUs `cpus` (bit n: CPU n; none: CPU 0); the clock
    /// reads `now`.
    pub fn with_cpus(now: u64, cpus: u64) -> Self {
        let cpus = cpus & ((1 << MAX_CPUS) - 1);
        Self {
            entries: [None; MAX_PROCESSES],
            reached: 0,
            cpus: if cpus == 0 { 1 } else { cpus },
            next_order: 0,
            last: now,
            sender: None,
            outside: false,
            head: [None; MAX_CPUS],
            turn: [None; MAX_CPUS],
            dirty: true,
            due: None,
            generation: 0,
            contended: [false; MAX_CPUS],
        }
    }

    /// The CPU a thread not placed elsewhere runs on: the guest's lowest, where its own
    /// thread and so every thread it creates start.
    fn first_cpu(&self) -> u8 {
        self.cpus.trailing_zeros() as u8
    }

    /// The guest's CPUs, ascending.
    fn cpu_list(&self) -> impl Iterator<Item = u8> + use<> {
        let cpus = self.cpus;
        (0..MAX_CPUS as u8).filter(move |&cpu| cpus >> cpu & 1 != 0)
    }

    fn index(&self, pid: u32) -> Option<usize> {
        self.entries[..self.reached]
            .iter()
            .position(|e| e.is_some_and(|e| e.pid == pid))
    }

    /// The entry of `pid`, once it has joined (a fresh one has not).
    fn get(&self, pid: u32) -> Option<&Entry> {
        self.entries[..self.reached]
            .iter()
            .flatten()
            .find(|e| e.pid == pid && !e.fresh)
    }

    fn get_mut(&mut self, pid: u32) -> Option<&mut Entry> {
        self.entries[..self.reached]
            .iter_mut()
            .flatten()
            .find(|e| e.pid == pid && !e.fresh)
    }

    /// The next place at a queue's tail.
    fn tail(&mut self) -> u64 {
        self.next_order += 1;
        self.next_order
    }

    /// A message of process `pid`'s thread arrived (a call, a fault, an interruption):
    /// it ran until now and waits for the answer.
    pub fn received(&mut self, pid: u32) {
        self.sender = Some(pid);
        if let Some(e) = self.get_mut(pid) {
            e.in_call = true;
        }
    }

    /// Another partition woke the guest (the NIC's frames rang a port's doorbell): the
    /// time since the guest last looked went, at least in part, to that partition and to
    /// the guest's work for it, so the next look charges it to the process the model says
    /// holds the CPU only if that one has made no call for [`STARVATION_NS`] (it spins:
    /// frames coming every moment must not spare it its turns for longer than others
    /// starve). (Charged to any, the NIC's work
    /// made short-lived processes CPU-bound, and a stream of connections then starved
    /// them: busybox httpd's children waited to exit until the task quota refused the
    /// next `fork`.)
    pub fn outside(&mut self) {
        self.outside = true;
    }

    /// The guest answered `pid`'s message: its thread joined the tail of its priority's
    /// queue. One the guest had seen waiting was woken (see [`Scheduler::decide`]). A
    /// process not seen before (a new child's first message) is added, interactive.
    pub fn replied(&mut self, pid: u32) {
        let (order, now, contended) = (self.tail(), self.last, self.contended);
        let Some(e) = self.get_mut(pid) else {
            return self.insert(pid, order);
        };
        e.in_call = false;
        e.answered = now;
        e.woken |= e.waiting_since.is_some() && !e.stopped;
        let contended = contended[e.cpu as usize];
        let changed = e.woken || (!e.cpu_bound && contended);
        if !e.cpu_bound {
            e.order = order;
        }
        self.dirty |= changed;
    }

    /// Process `pid` was stopped (`stop`) or continued.
    pub fn stopped(&mut self, pid: u32, stop: bool) {
        let (order, now) = (self.tail(), self.last);
        let Some(e) = self.get_mut(pid) else { return };
        e.stopped = stop;
        if stop {
            e.waiting_since.get_or_insert(now);
        } else if !e.in_call {
            e.order = order; // resumed: the tail of its queue
            e.woken = e.waiting_since.is_some();
        }
        self.dirty = true;
    }

    /// Process `pid`'s thread runs on `cpu` from now on (one of the guest's; another is the
    /// guest's first): placed when it was created, or moved while it waited. A CPU-bound
    /// one leaves the turn order of its old CPU for the back of its new one's. A thread not
    /// seen yet keeps its CPU until it joins at its first answer.
    pub fn set_cpu(&mut self, pid: u32, cpu: u32) {
        let cpu = if cpu < MAX_CPUS as u32 && self.cpus >> cpu & 1 != 0 {
            cpu as u8
        } else {
            self.first_cpu()
        };
        let order = self.tail();
        let Some(i) = self.index(pid) else {
            self.insert(pid, order);
            if let Some(e) = self.index(pid).and_then(|i| self.entries[i].as_mut()) {
                (e.cpu, e.fresh) = (cpu, true);
            }
            return;
        };
        let Some(e) = self.entries[i].as_mut() else {
            return;
        };
        let old = e.cpu as usize;
        if e.cpu == cpu {
            return;
        }
        e.cpu = cpu;
        if e.cpu_bound {
            e.order = order;
        }
        if self.turn[old] == Some(pid) {
            self.turn[old] = None;
        }
        self.dirty = true;
    }

    /// Wakes the process in slot `i` at `now`: interactive, with its debt (a CPU-bound
    /// one's: a slice) less the time it waited.
    fn wake(&mut self, i: usize, now: u64) {
        let order = self.next_order + 1;
        let Some(e) = self.entries[i].as_mut() else {
            return;
        };
        e.woken = false;
        let Some(since) = e.waiting_since.take() else {
            return;
        };
        let debt = if e.cpu_bound { SLICE_NS } else { e.used };
        e.used = debt.saturating_sub(now.saturating_sub(since));
        e.since = now;
        if e.cpu_bound {
            // Its new priority puts it at the interactive queue's tail.
            (e.cpu_bound, e.order) = (false, order);
            self.next_order = order;
        }
    }

    /// Adds `pid`: interactive, runnable, no debt, at the tail of the interactive queue,
    /// on the CPU it was placed on (a fresh entry's), else the guest's first.
    fn insert(&mut self, pid: u32, order: u64) {
        let now = self.last;
        let placed = self.index(pid);
        let cpu = placed
            .and_then(|i| self.entries[i])
            .map_or(self.first_cpu(), |e| e.cpu);
        let free = self.entries[..self.reached]
            .iter()
            .position(Option::is_none);
        let Some(i) = placed
            .or(free)
            .or((self.reached < MAX_PROCESSES).then_some(self.reached))
        else {
            return;
        };
        self.reached = self.reached.max(i + 1);
        self.entries[i] = Some(Entry {
            pid,
            cpu,
            fresh: false,
            cpu_bound: false,
            in_call: false,
            stopped: false,
            waiting_since: None,
            woken: false,
            used: 0,
            order,
            since: now,
            answered: now,
        });
        self.dirty = true;
    }

    /// Process `pid` ended.
    pub fn forget(&mut self, pid: u32) {
        if let Some(i) = self.index(pid) {
            self.entries[i] = None;
            self.dirty = true;
        }
        for turn in &mut self.turn {
            if *turn == Some(pid) {
                *turn = None;
            }
        }
    }

    /// The runnable processes on `cpu` at a glance (one pass over the table).
    fn view(&self, cpu: u8) -> View {
        let mut v = View::default();
        for (i, e) in self.entries[..self.reached].iter().enumerate() {
            let Some(e) = e.filter(|e| e.runnable() && e.cpu == cpu) else {
                continue;
            };
            v.runnable += 1;
            let first = if e.cpu_bound {
                v.cpu_bound += 1;
                &mut v.first_bound
            } else {
                &mut v.first_interactive
            };
            if first.is_none_or(|(_, order)| e.order < order) {
                *first = Some((i, e.order));
            }
        }
        v
    }

    /// The process the model says holds the guest's first CPU ([`Scheduler::running_on`]).
    pub fn running(&self) -> Option<u32> {
        self.running_on(self.first_cpu() as u32)
    }

    /// The process the model says holds `cpu`: its first runnable interactive one in the
    /// kernel's queue order, else the one whose turn it is.
    pub fn running_on(&self, cpu: u32) -> Option<u32> {
        let v = self.view(u8::try_from(cpu).ok()?);
        let (i, _) = v.first_interactive.or(v.first_bound)?;
        self.entries[i].map(|e| e.pid)
    }

    /// The CPU `pid`'s thread runs on, as [`Scheduler::set_cpu`] last said (a thread not
    /// placed: the guest's first).
    pub fn cpu(&self, pid: u32) -> u32 {
        self.index(pid)
            .and_then(|i| self.entries[i])
            .map_or(self.first_cpu(), |e| e.cpu) as u32
    }

    /// Counts the decisions that may have changed a [`Scheduler::level`]: the priorities
    /// need setting again only when it changed.
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// Charges `ns` that ended `now` to `pid`: it held its CPU. One that is unanswered
    /// waits from now.
    fn charge(&mut self, pid: u32, ns: u64, now: u64) {
        let Some(e) = self.get_mut(pid) else {
            return;
        };
        e.used = e.used.saturating_add(ns);
        if !e.cpu_bound {
            e.used = e.used.min(SLICE_NS);
        }
        e.since = now;
        let waits = e.in_call && e.waiting_since.is_none();
        if waits {
            e.waiting_since = Some(now);
        }
        let spent = e.spent();
        self.dirty |= waits || spent;
    }

    /// The guest looks at `now`: the time since it last looked is charged, on the CPU of
    /// the process whose message arrived, to that sender, and on every other CPU (or
    /// without a message: a time-out, console input) to the one the model said would run
    /// there; the sender, if still unanswered, waits from now. The processes answered
    /// after a wait are woken now: interactive, with their debt (a CPU-bound one's: a
    /// slice) less the time they waited. Then the decisions due are made, CPU by CPU:
    /// interactive processes whose debt reached a slice become CPU-bound (at the back of
    /// their CPU's turn order), the turn passes on after a slice, starving CPU-bound
    /// processes become interactive. Returns when the next decision is due (the slice of
    /// the process that runs on a CPU ends while another may run there, or a CPU-bound
    /// process starts to starve), if any: the guest looks again then even if nothing else
    /// happens.
    pub fn decide(&mut self, now: u64) -> Option<u64> {
        let ns = now.saturating_sub(self.last);
        self.last = now;
        let outside = core::mem::take(&mut self.outside);
        let spins = |e: &Entry| now.saturating_sub(e.answered) >= STARVATION_NS;
        let sender = self.sender.take();
        let sender_cpu = sender.map(|pid| self.get(pid).map_or(self.first_cpu(), |e| e.cpu));
        for cpu in self.cpu_list() {
            let charged = match sender {
                Some(pid) if sender_cpu == Some(cpu) => Some(pid),
                _ => self.head[cpu as usize]
                    .filter(|&pid| !outside || self.get(pid).is_some_and(spins)),
            };
            if let Some(pid) = charged {
                self.charge(pid, ns, now);
            }
        }
        if !self.dirty && self.due.is_none_or(|at| now < at) {
            return self.due;
        }
        for i in 0..self.reached {
            if self.entries[i].is_some_and(|e| e.woken) {
                self.wake(i, now);
            }
        }
        self.dirty = false;
        self.generation += 1;
        self.due = self.remake(now);
        self.due
    }

    /// The decisions of [`Scheduler::decide`], remade from the table.
    fn remake(&mut self, now: u64) -> Option<u64> {
        for i in 0..self.reached {
            if self.entries[i].is_some_and(|e| e.runnable() && !e.cpu_bound && e.spent()) {
                let order = self.tail();
                if let Some(e) = self.entries[i].as_mut() {
                    (e.cpu_bound, e.used, e.order) = (true, 0, order);
                }
            }
        }
        let mut due: Option<u64> = None;
        for cpu in self.cpu_list() {
            if let Some(at) = self.remake_cpu(cpu, now) {
                due = Some(due.map_or(at, |d| d.min(at)));
            }
        }
        due
    }

    /// The decisions of one CPU: its turn, its aging, who holds it; when its next
    /// decision is due.
    fn remake_cpu(&mut self, cpu: u8, now: u64) -> Option<u64> {
        let c = cpu as usize;
        let starves = |e: &Entry| now.saturating_sub(e.since) >= STARVATION_NS;
        let mut v = self.view(cpu);
        self.pass_turn(cpu, &v);
        // The holder's slice is over: the next in turn order, if any, has the turn.
        if let Some((i, _)) = v.first_bound
            && self.entries[i].is_some_and(|e| e.spent())
        {
            let order = self.tail();
            if let Some(e) = self.entries[i].as_mut() {
                e.used = 0;
                if v.cpu_bound > 1 {
                    e.order = order;
                }
            }
            v = self.view(cpu);
            self.pass_turn(cpu, &v);
        }
        // The CPU-bound processes that starve: a slice at the top, each.
        if v.first_interactive.is_some() {
            let mut aged = false;
            for i in 0..self.reached {
                if self.entries[i]
                    .is_some_and(|e| e.cpu == cpu && e.cpu_bound && e.runnable() && starves(&e))
                {
                    let order = self.tail();
                    if let Some(e) = self.entries[i].as_mut() {
                        (e.cpu_bound, e.used, e.order, e.since) = (false, 0, order, now);
                    }
                    aged = true;
                }
            }
            if aged {
                v = self.view(cpu);
                self.pass_turn(cpu, &v);
            }
        }

        self.contended[c] = v.runnable - v.cpu_bound > 1;
        self.head[c] = v
            .first_interactive
            .or(v.first_bound)
            .and_then(|(i, _)| self.entries[i])
            .map(|e| e.pid);
        let entry = |first: Option<(usize, u64)>| first.and_then(|(i, _)| self.entries[i]);
        let holder = entry(v.first_bound);
        let slice_end = match entry(v.first_interactive) {
            Some(e) if v.runnable > 1 => Some(e.used),
            Some(_) => None,
            None => holder.filter(|_| v.cpu_bound > 1).map(|e| e.used),
        }
        .map(|used| now + SLICE_NS.saturating_sub(used));
        let starving = v.first_interactive.and_then(|_| {
            self.entries[..self.reached]
                .iter()
                .flatten()
                .filter(|e| e.cpu == cpu && e.cpu_bound && e.runnable())
                .map(|e| e.since + STARVATION_NS)
                .min()
        });
        match (slice_end, starving) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Gives `cpu`'s turn to its first runnable CPU-bound process in turn order (`v`), if
    /// it is not the holder already (its slice starts now; how long it has not run, which
    /// ages it, goes on).
    fn pass_turn(&mut self, cpu: u8, v: &View) {
        let next = v
            .first_bound
            .and_then(|(i, _)| self.entries[i])
            .map(|e| e.pid);
        if next != self.turn[cpu as usize] {
            self.turn[cpu as usize] = next;
            if let Some((i, _)) = v.first_bound
                && let Some(e) = self.entries[i].as_mut()
            {
                e.used = 0;
            }
        }
    }

    /// The level `pid`'s thread belongs at (a process not seen yet: interactive).
    pub fn level(&self, pid: u32) -> Level {
        match self.get(pid) {
            Some(e) if e.cpu_bound && self.turn[e.cpu as usize] == Some(pid) => Level::Turn,
            Some(e) if e.cpu_bound => Level::Queued,
            _ => Level::Interactive,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::VecDeque;

    const MS: u64 = 1_000_000;
    const US: u64 = 1_000;

    /// Process `pid` makes a call that is answered at once.
    fn call(s: &mut Scheduler, pid: u32) {
        s.received(pid);
        s.replied(pid);
    }

    #[test]
    fn levels_are_three_priorities_in_a_row() {
        assert_eq!(Level::Interactive.below_top(), 0);
        assert_eq!(Level::Turn.below_top(), 1);
        assert_eq!(Level::Queued.below_top(), 2);
    }

    #[test]
    fn a_process_that_spins_a_slice_beside_another_runs_in_turns() {
        let mut s = Scheduler::new(0);
        s.replied(1);
        s.replied(2);
        assert_eq!(s.decide(0), Some(SLICE_NS), "the slice of the first ends");
        assert_eq!(s.running(), Some(1));
        assert_eq!(s.level(1), Level::Interactive);
        let before = s.generation();
        assert_eq!(
            s.decide(SLICE_NS / 2),
            Some(SLICE_NS),
            "nothing to decide yet"
        );
        assert_eq!(s.generation(), before, "no level changed");
        s.decide(SLICE_NS);
        assert_eq!(s.level(1), Level::Turn, "alone of the CPU-bound: its turn");
        assert_eq!(s.level(2), Level::Interactive);
        assert_eq!(s.running(), Some(2));
        s.decide(2 * SLICE_NS);
        assert_eq!(
            (s.level(1), s.level(2)),
            (Level::Turn, Level::Queued),
            "the second is CPU-bound too, behind the first"
        );
        assert_eq!(s.running(), Some(1));
        assert_eq!(s.decide(2 * SLICE_NS), Some(3 * SLICE_NS));
        s.decide(3 * SLICE_NS);
        assert_eq!((s.level(1), s.level(2)), (Level::Queued, Level::Turn));
        assert_eq!(s.running(), Some(2));
    }

    #[test]
    fn a_call_keeps_the_turn() {
        let mut s = Scheduler::new(0);
        s.replied(1);
        s.replied(2);
        s.decide(0);
        s.decide(SLICE_NS);
        s.decide(2 * SLICE_NS);
        assert_eq!((s.level(1), s.level(2)), (Level::Turn, Level::Queued));
        for k in 1..10 {
            call(&mut s, 1);
            s.decide(2 * SLICE_NS + k * MS);
            assert_eq!(s.level(1), Level::Turn, "{k} ms into its turn");
        }
        call(&mut s, 1);
        s.decide(3 * SLICE_NS);
        assert_eq!((s.level(1), s.level(2)), (Level::Queued, Level::Turn));
    }

    #[test]
    fn the_time_another_partition_takes_is_charged_only_to_a_spinning_process() {
        let mut s = Scheduler::new(0);
        s.replied(1);
        s.replied(2);
        s.decide(0);
        // Frames ring the guest's doorbell every 2 ms for a whole slice and more, and
        // process 1, the one the model says holds the CPU, makes a call after each: it
        // is charged its calls' 100 us, not the frames' time.
        for k in 1..=8 {
            s.outside();
            s.decide(k * 2 * MS);
            call(&mut s, 1);
            s.decide(k * 2 * MS + 100 * US);
        }
        assert_eq!(
            (s.level(1), s.level(2)),
            (Level::Interactive, Level::Interactive)
        );
        // Then it makes no call (and 2 waits in one): STARVATION_NS after its last, the
        // frames no longer spare it.
        s.received(2);
        for k in 9..=70 {
            s.outside();
            s.decide(k * 2 * MS);
        }
        assert_eq!(s.level(1), Level::Turn, "it kept the CPU: CPU-bound");
    }

    #[test]
    fn a_process_alone_is_left_alone() {
        let mut s = Scheduler::new(0);
        s.replied(1);
        assert_eq!(s.decide(0), None, "no other process: no time slice to end");
        assert_eq!(s.decide(5 * SLICE_NS), None);
        assert_eq!(s.level(1), Level::Turn, "it spun: CPU-bound, with the turn");
    }

    #[test]
    fn a_woken_process_is_interactive_with_its_debt_less_its_wait() {
        let mut s = Scheduler::new(0);
        s.replied(1);
        s.replied(2);
        s.decide(0);
        s.decide(SLICE_NS);
        s.decide(2 * SLICE_NS);
        assert_eq!((s.level(1), s.level(2)), (Level::Turn, Level::Queued));
        // Process 1 runs 1 ms of its turn and its call waits (a pipe)...
        let t = 2 * SLICE_NS + MS;
        s.received(1);
        s.decide(t);
        assert_eq!(s.level(2), Level::Turn, "the turn passed on");
        assert_eq!(s.running(), Some(2));
        // ... for 3 ms: then the call is answered and it is woken.
        let t = t + 3 * MS;
        s.received(2); // a call of process 2 writes into the pipe
        s.replied(1);
        s.replied(2);
        assert_eq!(
            s.decide(t),
            Some(t + 3 * MS),
            "its debt is a slice less the 3 ms it waited: 3 ms more make a slice"
        );
        assert_eq!(s.level(1), Level::Interactive, "woken: interactive again");
        assert_eq!(s.running(), Some(1), "it preempts the CPU-bound one");
        call(&mut s, 1);
        s.decide(t + 3 * MS);
        assert_eq!(
            s.level(1),
            Level::Queued,
            "CPU-bound again, behind the other"
        );

        // A wait of a slice or more forgives the whole debt.
        let t = t + 4 * MS;
        s.received(1);
        s.decide(t);
        s.decide(t + SLICE_NS);
        s.replied(1);
        assert_eq!(s.decide(t + SLICE_NS), Some(t + 2 * SLICE_NS));
        assert_eq!(s.level(1), Level::Interactive);
    }

    #[test]
    fn a_stopped_process_waits_and_is_woken_when_continued() {
        let mut s = Scheduler::new(0);
        s.replied(1);
        s.replied(2);
        s.decide(0);
        s.decide(SLICE_NS);
        s.decide(2 * SLICE_NS);
        assert_eq!((s.level(1), s.level(2)), (Level::Turn, Level::Queued));
        s.stopped(1, true);
        s.decide(2 * SLICE_NS);
        assert_eq!(s.running(), Some(2), "a stopped process does not run");
        assert_eq!(s.level(2), Level::Turn);
        s.stopped(1, false);
        s.decide(4 * SLICE_NS);
        assert_eq!(s.level(1), Level::Interactive, "continued after two slices");
        assert_eq!(s.running(), Some(1));
        // Stopped while its call waits: answered while stopped, woken when continued.
        s.received(1);
        s.decide(4 * SLICE_NS + MS);
        s.stopped(1, true);
        s.replied(1);
        s.decide(5 * SLICE_NS);
        assert_eq!(s.running(), Some(2));
        s.stopped(1, false);
        s.decide(5 * SLICE_NS);
        assert_eq!(s.running(), Some(1));
    }

    #[test]
    fn a_starving_turn_holder_runs_a_slice_beside_the_interactive_ones() {
        let mut s = Scheduler::new(0);
        s.replied(1);
        s.decide(0);
        s.decide(SLICE_NS);
        assert_eq!(s.level(1), Level::Turn);
        // Processes 2 and 3 are the ends of a busy pipe: each runs 1 ms, wakes the other
        // and waits as long as it ran; between them they keep the CPU.
        s.replied(2);
        s.replied(3);
        s.received(3);
        s.decide(SLICE_NS);
        let (mut t, mut due, mut ends) = (SLICE_NS, None, (2, 3));
        let starves = SLICE_NS + STARVATION_NS;
        while s.level(1) == Level::Turn {
            assert!(t < starves, "never aged");
            assert!(due.is_none_or(|at| at <= starves), "{due:?}: look by then");
            t += MS;
            s.received(ends.0);
            s.replied(ends.1);
            due = s.decide(t);
            ends = (ends.1, ends.0);
            if t < starves {
                assert_eq!(s.running(), Some(ends.0));
                assert_eq!(s.level(ends.0), Level::Interactive);
            }
        }
        assert_eq!(t, starves);
        assert_eq!(s.level(1), Level::Interactive, "aged: a slice at the top");
        assert_eq!(
            s.running(),
            Some(ends.0),
            "behind the pipe's end already queued"
        );
    }

    #[test]
    fn new_and_forgotten_processes() {
        let mut s = Scheduler::new(0);
        s.replied(7); // a new child's first message
        assert_eq!(s.level(7), Level::Interactive);
        s.decide(0);
        assert_eq!(s.running(), Some(7));
        s.forget(7);
        s.decide(0);
        assert_eq!(s.running(), None);
        assert_eq!(s.level(9), Level::Interactive, "unknown: interactive");
        s.received(9); // unknown: nothing to charge, no panic
        s.decide(MS);
        // The table never overflows: more pids than slots are left out, not a panic.
        for pid in 1..=MAX_PROCESSES as u32 + 4 {
            s.replied(pid);
        }
        s.decide(2 * MS);
    }

    /// What a simulated process does.
    #[derive(Clone, Copy, Debug)]
    enum Work {
        /// Spins in user code for ever.
        Spin,
        /// `count` system calls the guest answers at once, `between` ns of user code before
        /// each; then it is done.
        Calls { between: u64, count: u32 },
        /// Runs `run` ns, then sleeps `sleep` ns (a deferred reply the guest's timer ends),
        /// for ever; the time from each wake-up to running again is recorded.
        Sleeper { run: u64, sleep: u64 },
        /// Runs `run` ns, then wakes process `peer` and waits until `peer` wakes it (the
        /// two ends of a busy pipe).
        PingPong { run: u64, peer: u32 },
    }

    #[derive(Debug)]
    struct Proc {
        pid: u32,
        work: Work,
        /// User code left until its next message.
        left: u64,
        /// Waits in a call: until this time (a sleep), or for ever (`u64::MAX`).
        blocked_until: Option<u64>,
        level: Level,
        done_at: Option<u64>,
        cpu: u64,
        /// When it was last woken and has not run since.
        woken_at: Option<u64>,
        /// The longest time from a wake-up to running.
        worst_latency: u64,
    }

    /// The kernel's ready queues (one per level, FIFO, the running thread at its head)
    /// and the guest's main loop around a [`Scheduler`], as `main.rs` drives it; `flat`
    /// keeps every process interactive (the guest before this policy, without its round
    /// robin).
    struct Sim {
        t: u64,
        procs: Vec<Proc>,
        ready: [VecDeque<u32>; 3],
        sched: Scheduler,
        /// Time the guest takes to serve a message.
        serve: u64,
        flat: bool,
        /// Who ran when, how long.
        ran: Vec<(u64, u32, u64)>,
    }

    impl Sim {
        fn new(works: &[Work]) -> Self {
            let mut sim = Sim {
                t: 0,
                procs: Vec::new(),
                ready: Default::default(),
                sched: Scheduler::new(0),
                serve: 5 * US,
                flat: false,
                ran: Vec::new(),
            };
            for (i, &work) in works.iter().enumerate() {
                let pid = i as u32 + 1;
                let left = match work {
                    Work::Spin => u64::MAX,
                    Work::Calls { between, .. } => between,
                    Work::Sleeper { run, .. } | Work::PingPong { run, .. } => run,
                };
                sim.procs.push(Proc {
                    pid,
                    work,
                    left,
                    blocked_until: None,
                    level: Level::Interactive,
                    done_at: None,
                    cpu: 0,
                    woken_at: None,
                    worst_latency: 0,
                });
                sim.reply(pid);
            }
            sim
        }

        fn proc(&mut self, pid: u32) -> &mut Proc {
            &mut self.procs[pid as usize - 1]
        }

        /// The kernel: the thread at the head of the highest non-empty queue.
        fn head(&self) -> Option<u32> {
            self.ready.iter().find_map(|q| q.front().copied())
        }

        fn unqueue(&mut self, pid: u32) {
            for q in &mut self.ready {
                q.retain(|&p| p != pid);
            }
        }

        /// The guest answers `pid`: its thread joins the tail of its priority's queue.
        fn reply(&mut self, pid: u32) {
            self.unqueue(pid);
            let level = self.proc(pid).level;
            self.ready[level.below_top() as usize].push_back(pid);
            self.sched.replied(pid);
        }

        fn wake(&mut self, pid: u32) {
            let t = self.t;
            let p = self.proc(pid);
            p.blocked_until = None;
            p.woken_at = Some(t);
            self.reply(pid);
        }

        /// The guest looks: decide, set the priorities; when the next decision is due.
        fn look(&mut self) -> Option<u64> {
            let due = self.sched.decide(self.t);
            for i in 0..self.procs.len() {
                let pid = self.procs[i].pid;
                let level = if self.flat {
                    Level::Interactive
                } else {
                    self.sched.level(pid)
                };
                if self.procs[i].level != level {
                    self.procs[i].level = level;
                    if self.ready.iter().any(|q| q.contains(&pid)) {
                        // thread_set of a priority: the tail of the new one's queue.
                        self.unqueue(pid);
                        self.ready[level.below_top() as usize].push_back(pid);
                    }
                }
            }
            due
        }

        /// Runs until `end`.
        fn run(&mut self, end: u64) {
            while self.t < end {
                let due = self.look();
                let wake = self.procs.iter().filter_map(|p| p.blocked_until).min();
                let limit = [due, wake, Some(end)].into_iter().flatten().min();
                let limit = limit.unwrap_or(end).max(self.t);
                let Some(pid) = self.head() else {
                    self.t = limit;
                    self.wake_due();
                    continue;
                };
                let t = self.t;
                let p = self.proc(pid);
                if let Some(at) = p.woken_at.take() {
                    p.worst_latency = p.worst_latency.max(t - at);
                }
                let slice = p.left.min(limit - t);
                p.left -= slice;
                p.cpu += slice;
                self.ran.push((t, pid, slice));
                self.t += slice;
                if self.proc(pid).left == 0 {
                    self.message(pid);
                    self.t += self.serve;
                }
                self.wake_due();
            }
        }

        fn wake_due(&mut self) {
            let t = self.t;
            let due: Vec<u32> = self
                .procs
                .iter()
                .filter(|p| p.blocked_until.is_some_and(|at| at <= t))
                .map(|p| p.pid)
                .collect();
            for pid in due {
                self.wake(pid);
            }
        }

        /// `pid` finished its user code: the message it sends, as the guest serves it.
        fn message(&mut self, pid: u32) {
            self.sched.received(pid);
            let t = self.t;
            match self.proc(pid).work {
                Work::Spin => unreachable!(),
                Work::Calls { between, count } => {
                    let p = self.proc(pid);
                    p.work = Work::Calls {
                        between,
                        count: count - 1,
                    };
                    if count == 1 {
                        p.done_at = Some(t);
                        self.unqueue(pid);
                        self.sched.forget(pid);
                    } else {
                        p.left = between;
                        self.reply(pid);
                    }
                }
                Work::Sleeper { run, sleep } => {
                    let p = self.proc(pid);
                    p.left = run;
                    p.blocked_until = Some(t + sleep);
                    self.unqueue(pid);
                }
                Work::PingPong { run, peer } => {
                    let p = self.proc(pid);
                    p.left = run;
                    p.blocked_until = Some(u64::MAX);
                    self.unqueue(pid);
                    if self.proc(peer).blocked_until.is_some() {
                        self.wake(peer);
                    }
                }
            }
        }

        /// CPU time of `pid` in `from..to`.
        fn cpu_in(&self, pid: u32, from: u64, to: u64) -> u64 {
            self.ran
                .iter()
                .filter(|&&(at, p, _)| p == pid && at >= from && at < to)
                .map(|&(_, _, ns)| ns)
                .sum()
        }
    }

    #[test]
    fn calls_beside_a_spinner_run_at_full_speed_until_they_are_cpu_bound() {
        // 2,000 calls, 20 us of user code before each (plus 5 us of the guest's): 50 ms.
        let calls = Work::Calls {
            between: 20 * US,
            count: 2000,
        };
        let mut alone = Sim::new(&[calls]);
        alone.run(10_000 * MS);
        let alone_ns = alone.procs[0].done_at.expect("done alone");
        assert!(alone_ns <= 51 * MS, "alone: {alone_ns} ns");

        let mut beside = Sim::new(&[Work::Spin, calls]);
        beside.run(10_000 * MS);
        let beside_ns = beside.procs[1].done_at.expect("done beside a spinner");
        // The spinner's first slice, the caller's slice as an interactive process, then
        // half the CPU in turns.
        assert!(
            beside_ns <= 2 * alone_ns + 2 * SLICE_NS,
            "alone {alone_ns} ns, beside a spinner {beside_ns} ns"
        );

        // Every process at one priority: one call per time slice of the spinner's.
        let mut flat = Sim::new(&[Work::Spin, calls]);
        flat.flat = true;
        flat.run(1_000 * MS);
        assert!(
            flat.procs[1].done_at.is_none(),
            "the flat queue is no faster"
        );
        assert!(
            flat.procs[1].cpu < 5 * MS,
            "{} ns of CPU",
            flat.procs[1].cpu
        );
    }

    #[test]
    fn a_woken_process_runs_at_once_beside_spinners() {
        let mut sim = Sim::new(&[
            Work::Spin,
            Work::Spin,
            Work::Sleeper {
                run: 200 * US,
                sleep: 7 * MS,
            },
        ]);
        sim.run(2_000 * MS);
        let sleeper = &sim.procs[2];
        assert_eq!(sleeper.worst_latency, 0, "it runs when woken");
        assert!(sleeper.cpu > 50 * MS, "it ran {} ns", sleeper.cpu);
        let spun = [sim.procs[0].cpu, sim.procs[1].cpu];
        assert!(spun[0].abs_diff(spun[1]) <= 2 * SLICE_NS, "{spun:?}");
    }

    #[test]
    fn cpu_bound_processes_share_the_cpu_in_turns() {
        let mut sim = Sim::new(&[Work::Spin, Work::Spin, Work::Spin]);
        sim.run(3_000 * MS);
        let cpu: Vec<u64> = sim.procs.iter().map(|p| p.cpu).collect();
        let (min, max) = (cpu.iter().min().unwrap(), cpu.iter().max().unwrap());
        assert!(max - min <= 2 * SLICE_NS, "CPU times {cpu:?}");
        // In turns: over any 5 slices (after the first three), each ran at least one.
        for from in (3..290).map(|k| k * SLICE_NS) {
            for pid in 1..=3 {
                assert!(
                    sim.cpu_in(pid, from, from + 5 * SLICE_NS) >= SLICE_NS / 2,
                    "process {pid} starved from {from} ns"
                );
            }
        }
    }

    #[test]
    fn spinners_beside_a_busy_pipe_are_not_starved() {
        let mut sim = Sim::new(&[
            Work::PingPong {
                run: 100 * US,
                peer: 2,
            },
            Work::PingPong {
                run: 100 * US,
                peer: 1,
            },
            Work::Spin,
            Work::Spin,
        ]);
        // The pipe's reader starts waiting for the writer.
        sim.procs[1].blocked_until = Some(u64::MAX);
        sim.unqueue(2);
        sim.sched.received(2);
        sim.run(3_000 * MS);
        // Each spinner gets a slice in every period of aging.
        let period = STARVATION_NS + 2 * SLICE_NS;
        for from in (0..25).map(|k| k * period) {
            for spinner in [3, 4] {
                assert!(
                    sim.cpu_in(spinner, from, from + period) >= SLICE_NS / 2,
                    "no CPU for spinner {spinner} from {from} ns"
                );
            }
        }
        for p in &sim.procs[2..] {
            assert!(p.cpu >= 3_000 * MS / period / 2 * SLICE_NS / 2, "{p:?}");
        }
        let pipe = sim.procs[0].cpu + sim.procs[1].cpu;
        assert!(pipe > 2_000 * MS, "the pipe ran {pipe} ns");
    }

    #[test]
    fn placement_takes_the_least_loaded_allowed_cpu_and_prefers_its_own_among_equals() {
        let mut load: Load = [0; MAX_CPUS];
        assert_eq!(place(0b110, 1, &load), 1, "equals: the preferred CPU");
        assert_eq!(
            place(0b110, 5, &load),
            1,
            "equals, preferred not allowed: the lowest"
        );
        assert_eq!(place(0b010, 2, &load), 1, "only one allowed");
        assert_eq!(place(0, 3, &load), 3, "nothing allowed: where it is");
        load[1] = 1;
        assert_eq!(place(0b110, 1, &load), 2, "fewer runnable on CPU 2");
        load[2] = 1;
        assert_eq!(place(0b110, 2, &load), 2);
        assert_eq!(place(0b1010, 3, &load), 3, "CPU 3 is idle");
        // `xargs -P2 gzip` on CPUs 1 and 2: xargs (not counted) forks the first gzip onto
        // its own CPU, the second onto the other, and waits.
        let mut load: Load = [0; MAX_CPUS];
        let first = place(0b110, 1, &load);
        load[first as usize] += 1;
        let second = place(0b110, 1, &load);
        assert_eq!((first, second), (1, 2));
        // Bits beyond the kernel's eight CPUs are no CPU.
        assert_eq!(place(1 << 40 | 0b100, 2, &[0; MAX_CPUS]), 2);
    }

    #[test]
    fn each_cpu_has_its_own_turn() {
        // Two spinners on CPUs 1 and 2 of a guest with both: each is alone among the
        // CPU-bound processes of its CPU, so each keeps its turn; a third on CPU 1 takes
        // turns with the first only.
        let mut s = Scheduler::with_cpus(0, 0b110);
        for (pid, cpu) in [(1, 1), (2, 2), (3, 1)] {
            s.set_cpu(pid, cpu);
            assert_eq!(s.cpu(pid), cpu);
            assert_eq!(s.level(pid), Level::Interactive, "placed, not yet answered");
        }
        s.replied(1);
        s.replied(2);
        s.decide(0);
        assert_eq!((s.running_on(1), s.running_on(2)), (Some(1), Some(2)));
        assert_eq!(s.running(), Some(1), "the guest's first CPU");
        s.decide(SLICE_NS);
        assert_eq!(
            (s.level(1), s.level(2)),
            (Level::Turn, Level::Turn),
            "both ran a slice at once, each on its CPU"
        );
        for k in 2..20 {
            s.decide(k * SLICE_NS);
            assert_eq!((s.level(1), s.level(2)), (Level::Turn, Level::Turn), "{k}");
        }
        s.replied(3);
        let t = 20 * SLICE_NS;
        s.decide(t);
        assert_eq!(s.running_on(1), Some(3), "new: interactive, above the turn");
        s.decide(t + SLICE_NS);
        assert_eq!(
            (s.level(1), s.level(3), s.level(2)),
            (Level::Turn, Level::Queued, Level::Turn)
        );
        s.decide(t + 2 * SLICE_NS);
        assert_eq!(
            (s.level(1), s.level(3), s.level(2)),
            (Level::Queued, Level::Turn, Level::Turn),
            "CPU 1's turn passed; CPU 2's did not"
        );
        // Moved (while it waited) to CPU 2, the holder leaves CPU 1's turn to the other
        // and queues behind CPU 2's holder.
        s.received(3);
        s.set_cpu(3, 2);
        s.replied(3);
        s.decide(t + 2 * SLICE_NS + MS);
        assert_eq!(
            (s.level(1), s.level(2), s.level(3)),
            (Level::Turn, Level::Turn, Level::Queued)
        );
        assert_eq!(s.cpu(3), 2);
        // A CPU not the guest's places nowhere but the first.
        s.set_cpu(9, 5);
        assert_eq!(s.cpu(9), 1);
    }

    #[test]
    fn a_spinner_is_charged_while_another_cpu_sends_messages() {
        // Process 1 spins on CPU 1; process 2 on CPU 2 makes a call every millisecond.
        // On one CPU the caller's messages would mean process 1 did not run; here it ran
        // all the time, and becomes CPU-bound after a slice.
        let mut s = Scheduler::with_cpus(0, 0b110);
        s.set_cpu(1, 1);
        s.set_cpu(2, 2);
        s.replied(1);
        s.replied(2);
        s.decide(0);
        for k in 1..=10 {
            call(&mut s, 2);
            s.decide(k * MS);
        }
        assert_eq!(
            s.level(1),
            Level::Turn,
            "CPU-bound after a slice on its CPU"
        );
        assert_eq!(s.level(2), Level::Turn, "the caller ran its slice on CPU 2");
        // With one CPU, the same messages leave the spinner uncharged.
        let mut s = Scheduler::new(0);
        s.replied(1);
        s.replied(2);
        s.decide(0);
        for k in 1..=10 {
            call(&mut s, 2);
            s.decide(k * MS);
        }
        assert_eq!(s.level(1), Level::Interactive);
    }
}
