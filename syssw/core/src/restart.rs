//! Partition restarts handed from syssw's server thread to its restart worker: the queue of
//! restarts in order, whether the worker waits for one, and the two messages between them.
//!
//! Why a worker: reloading and zeroing a partition's memory and mapping it again take
//! milliseconds (many long kernel calls). The server thread must keep answering every other
//! partition meanwhile, and the work must be paid for by the restarted partition's own
//! windows. So the server does only the quick part at once (forget the old task, reset its
//! ports) and queues the rest here; the worker, a second thread of syssw,
//! asks for a job with an IPC `call` that the server answers (a deferred reply) once one is
//! queued, runs it in the restarted partition's time partition at its priority, and reports
//! the new instance (or the failure) with its next `call`, which asks for the next job at
//! the same time. The server records the instance and starts its first thread.
//!
//! Who kills the old task and prints the health monitor's line about the error that caused
//! the restart: the worker, first thing in the partition's window, when the job starts at
//! once ([`Restarts::worker_idle`]) and the partition has windows (the record is left for
//! it next to the job, `syssw/src/restart.rs`); else (the worker is busy with another
//! partition, or a background partition restarts) the server stops the old task at once
//! (`task_stop`, a bounded kernel call), so that no thread of a partition being restarted
//! ever runs on, and prints the line, and the worker destroys the task when the job starts.
//! The worker always destroys it, in the partition's own time (its windows, or the
//! background at its priority): the server, above every partition in every window, never
//! does, or a large partition's teardown would take another partition's window. So in a
//! restart loop the server's share of a fault report is its bookkeeping and one reply:
//! short, however large the partition, when the partition's window ends in the middle of
//! it (the next window starts late by that much at most).
//!
//! Invariants kept here: a partition is queued or being restarted at most once (its old
//! task is dead from the moment it is queued, so nothing of it can ask for another restart
//! until the worker reports back); jobs run in the order they were queued; the worker has at
//! most one job. A report for a partition the worker was not restarting is refused (only the
//! worker can send one, so that would be a bug of syssw, which the glue treats as fatal).
//! Nothing cancels a job: a partition without a task cannot fault or ask for anything, and a
//! module shutdown halts at once, whatever the worker is building.
//!
//! On a machine of several CPUs syssw's server thread runs on the CPU of the partition it
//! serves (it follows its callers) and the worker moves to the restarted partition's CPU
//! with its time partition ([`worker_place`]), so a restart costs that partition's windows
//! on its own CPU, as on one CPU.
//!
//! This module must never make a system call: the glue (`syssw/src/server.rs`,
//! `syssw/src/restart.rs`) moves the messages.

use config::binary::PartitionView;
use config::model::{MAX_PARTITIONS, SYSSW_PRIORITY};
use protocol::StartCondition;

/// Whether the worker runs a restart of `p` in `p`'s own windows: `p` has windows. Only
/// then is the old task left for the worker to kill first thing in the partition's window;
/// otherwise the server stops it at once.
pub fn in_own_windows(p: &PartitionView) -> bool {
    p.time_partition != 0
}

/// Where the worker runs the restart of `p`: (CPU, time partition, priority). On `p`'s CPU
/// and in its time partition, so that its windows pay for the reload: at
/// [`SYSSW_PRIORITY`] there (above every thread of the partition it may have to kill,
/// below the server), or for a background partition at its priority (it competes for its
/// CPU's background as the partition itself would).
pub fn worker_place(p: &PartitionView) -> (u8, u8, u8) {
    match p.time_partition {
        0 => (p.cpu, 0, p.priority),
        tp => (p.cpu, tp, SYSSW_PRIORITY),
    }
}

/// How the restarted instance starts (ARINC: cold reloads the memory from the image, warm
/// keeps it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kind {
    Cold,
    Warm,
}

/// One restart for the worker.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Job {
    /// The partition's index in the configuration.
    pub partition: usize,
    pub kind: Kind,
    /// ARINC START_CONDITION for the start record.
    pub condition: StartCondition,
    /// The partition's restarts so far, this one included (for the mode-change log line).
    pub restarts: u32,
    /// The old task the worker kills first, in the partition's time (the server may have
    /// stopped it already; `None`: there was none).
    pub kill: Option<u64>,
}

impl Job {
    /// The reply words that hand the job to the worker.
    pub fn to_words(self) -> [u64; 3] {
        let kind = match self.kind {
            Kind::Cold => 1,
            Kind::Warm => 2,
        };
        [
            self.partition as u64 | kind << 8 | (self.condition as u64) << 16,
            u64::from(self.restarts),
            self.kill.unwrap_or(0),
        ]
    }

    /// The job in a reply from the server (`None`: not a job). Task ids are never 0.
    pub fn from_words(words: [u64; 3]) -> Option<Self> {
        let kind = match (words[0] >> 8) & 0xff {
            1 => Kind::Cold,
            2 => Kind::Warm,
            _ => return None,
        };
        let partition = (words[0] & 0xff) as usize;
        if partition >= MAX_PARTITIONS || words[0] >> 24 != 0 {
            return None;
        }
        Some(Job {
            partition,
            kind,
            condition: StartCondition::from_u64((words[0] >> 16) & 0xff)?,
            restarts: u32::try_from(words[1]).ok()?,
            kill: (words[2] != 0).then_some(words[2]),
        })
    }
}

/// What the worker says when it asks for its next job.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Report {
    /// Its first call: no job done yet.
    Ready,
    /// The partition's new instance is built (its first thread not started yet).
    Done {
        partition: usize,
        task: u64,
        thread: u64,
    },
    /// The restart failed (the worker logged why and left nothing of the new instance).
    Failed { partition: usize },
}

/// Labels of the worker's calls (only the worker thread sends them: the server tells it
/// apart by the sender the kernel reports, never by the label).
const LABEL_READY: u32 = 1;
const LABEL_DONE: u32 = 2;
const LABEL_FAILED: u32 = 3;

impl Report {
    /// Label and words of the worker's call.
    pub fn encode(self) -> (u32, [u64; 3]) {
        match self {
            Report::Ready => (LABEL_READY, [0; 3]),
            Report::Done {
                partition,
                task,
                thread,
            } => (LABEL_DONE, [partition as u64, task, thread]),
            Report::Failed { partition } => (LABEL_FAILED, [partition as u64, 0, 0]),
        }
    }

    pub fn decode(label: u32, words: [u64; 3]) -> Option<Self> {
        let partition = usize::try_from(words[0]).ok();
        match label {
            LABEL_READY => Some(Report::Ready),
            LABEL_DONE => Some(Report::Done {
                partition: partition?,
                task: words[1],
                thread: words[2],
            }),
            LABEL_FAILED => Some(Report::Failed {
                partition: partition?,
            }),
            _ => None,
        }
    }

    /// The partition this report finishes, if any.
    pub fn partition(self) -> Option<usize> {
        match self {
            Report::Ready => None,
            Report::Done { partition, .. } | Report::Failed { partition } => Some(partition),
        }
    }
}

/// Why a worker's report was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReportError {
    /// It finishes a partition the worker was not restarting.
    NotItsJob(usize),
    /// It asks for a job while it still had one (a `Ready` after a dispatch).
    JobLost(usize),
    /// The worker asked twice without a reply in between (impossible over IPC `call`).
    AlreadyWaiting,
}

/// The restarts waiting for the worker and the worker's state.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Restarts {
    /// Queued jobs in order: `queue[(head + i) % MAX_PARTITIONS]` for `i < len`.
    queue: [Option<Job>; MAX_PARTITIONS],
    head: usize,
    len: usize,
    /// The job the worker is running.
    running: Option<Job>,
    /// The worker has called and waits for the reply that hands it a job.
    worker_waiting: bool,
}

impl Default for Restarts {
    fn default() -> Self {
        Self::new()
    }
}

impl Restarts {
    pub const fn new() -> Self {
        Restarts {
            queue: [None; MAX_PARTITIONS],
            head: 0,
            len: 0,
            running: None,
            worker_waiting: false,
        }
    }

    /// The partition is queued or being restarted (it has no task meanwhile).
    pub fn restarting(&self, partition: usize) -> bool {
        self.running.is_some_and(|j| j.partition == partition)
            || self.queued().any(|j| j.partition == partition)
    }

    fn queued(&self) -> impl Iterator<Item = Job> + '_ {
        (0..self.len).filter_map(|i| self.queue[(self.head + i) % MAX_PARTITIONS])
    }

    /// `task` is the old task the running job kills (alive until the worker gets to it:
    /// its threads' faults belong to no partition any more).
    pub fn dying(&self, task: u64) -> bool {
        self.running.is_some_and(|j| j.kill == Some(task))
    }

    /// The worker waits and nothing is queued: a job queued now starts at once.
    pub fn worker_idle(&self) -> bool {
        self.worker_waiting && self.len == 0
    }

    /// Jobs queued and not yet handed to the worker.
    pub fn waiting(&self) -> usize {
        self.len
    }

    /// Queues a restart; false (nothing queued) if the partition is already queued or being
    /// restarted, or `job.partition` is no partition index.
    pub fn push(&mut self, job: Job) -> bool {
        if job.partition >= MAX_PARTITIONS || self.restarting(job.partition) {
            return false;
        }
        // At most one entry per partition, so the ring never overflows.
        self.queue[(self.head + self.len) % MAX_PARTITIONS] = Some(job);
        self.len += 1;
        true
    }

    /// The worker's call: records what it finished and that it now waits for a job. The
    /// finished partition is returned for the glue to record (`Done`) or stop (`Failed`).
    pub fn report(&mut self, report: Report) -> Result<Option<usize>, ReportError> {
        if self.worker_waiting {
            return Err(ReportError::AlreadyWaiting);
        }
        let finished = match (report.partition(), self.running) {
            (None, None) => None,
            (None, Some(job)) => return Err(ReportError::JobLost(job.partition)),
            (Some(p), Some(job)) if job.partition == p => Some(p),
            (Some(p), _) => return Err(ReportError::NotItsJob(p)),
        };
        self.running = None;
        self.worker_waiting = true;
        Ok(finished)
    }

    /// The next job to hand to the worker, if it waits and one is queued (it is then the
    /// running job; the glue replies it to the worker).
    pub fn dispatch(&mut self) -> Option<Job> {
        if !self.worker_waiting || self.len == 0 {
            return None;
        }
        let job = self.queue[self.head].take();
        self.head = (self.head + 1) % MAX_PARTITIONS;
        self.len -= 1;
        self.running = job;
        self.worker_waiting = false;
        job
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn cold(partition: usize) -> Job {
        Job {
            partition,
            kind: Kind::Cold,
            condition: StartCondition::HmPartitionRestart,
            restarts: 1,
            kill: None,
        }
    }

    fn done(partition: usize) -> Report {
        Report::Done {
            partition,
            task: 7,
            thread: 9,
        }
    }

    #[test]
    fn the_worker_restarts_a_partition_on_its_cpu_in_its_windows() {
        // CPU 0: a (TP1, priority 100) and b (background, 50); CPU 1: c (TP2, 120) and d
        // (background, 60).
        let source =
            crate::testsys::with(&[("memory = \"512MiB\"", "cpus = 2"), ("# tail", C_AND_D)]);
        let blob = crate::testsys::blob(&source);
        let system = config::decode(&blob).unwrap();
        let partition = |name| system.find_partition(name).unwrap();
        let place = |name| worker_place(&partition(name));
        assert_eq!(place("a"), (0, 1, SYSSW_PRIORITY));
        assert_eq!(place("b"), (0, 0, 50));
        assert_eq!(place("c"), (1, 2, SYSSW_PRIORITY));
        assert_eq!(place("d"), (1, 0, 60));
        let own = |name| in_own_windows(&partition(name));
        assert!(own("a") && !own("b") && own("c") && !own("d"));
    }

    /// Partitions c (TP2 at 5 ms, priority 120) and d (background, 60) on CPU 1, for
    /// `testsys::TWO`'s `# tail`.
    const C_AND_D: &str = r#"[[schedules.windows]]
partition = "c"
offset = "5ms"
duration = "2ms"

[partitions.c]
image = "app"
memory = "1MiB"
kernel_memory = "64KiB"
max_priority = 120
cpus = [1]

[partitions.d]
image = "app"
memory = "1MiB"
kernel_memory = "64KiB"
max_priority = 60
time = "background"
cpus = [1]
"#;

    #[test]
    fn a_job_waits_until_the_worker_asks() {
        let mut r = Restarts::new();
        assert!(!r.worker_idle());
        assert!(r.push(cold(2)));
        assert!(r.restarting(2));
        assert_eq!(r.dispatch(), None, "the worker has not called yet");
        assert_eq!(r.report(Report::Ready), Ok(None));
        assert!(!r.worker_idle(), "a job waits");
        assert_eq!(r.dispatch(), Some(cold(2)));
        assert!(r.restarting(2), "running");
        assert_eq!(r.dispatch(), None, "one job at a time");
        assert_eq!(r.report(done(2)), Ok(Some(2)));
        assert!(!r.restarting(2));
        assert_eq!(r.dispatch(), None, "nothing queued");
    }

    #[test]
    fn the_worker_waiting_gets_the_next_job_at_once() {
        let mut r = Restarts::new();
        assert_eq!(r.report(Report::Ready), Ok(None));
        assert!(r.worker_idle());
        let job = Job {
            kill: Some(42),
            ..cold(0)
        };
        assert!(r.push(job));
        assert!(!r.dying(42), "queued, not running");
        assert_eq!(r.dispatch(), Some(job));
        assert!(r.dying(42) && !r.dying(43));
        r.report(done(0)).unwrap();
        assert!(!r.dying(42), "killed by now");
    }

    #[test]
    fn a_partition_is_queued_once() {
        let mut r = Restarts::new();
        assert!(r.push(cold(1)));
        assert!(!r.push(cold(1)), "queued");
        r.report(Report::Ready).unwrap();
        r.dispatch().unwrap();
        assert!(!r.push(cold(1)), "running");
        assert!(!r.push(cold(MAX_PARTITIONS)), "no such partition");
        assert_eq!(r.report(Report::Failed { partition: 1 }), Ok(Some(1)));
        assert!(r.push(cold(1)), "finished: it may fail again");
    }

    #[test]
    fn reports_must_match_the_running_job() {
        let mut r = Restarts::new();
        assert_eq!(r.report(done(0)), Err(ReportError::NotItsJob(0)));
        r.report(Report::Ready).unwrap();
        assert_eq!(r.report(Report::Ready), Err(ReportError::AlreadyWaiting));
        r.push(cold(3));
        r.dispatch().unwrap();
        assert_eq!(r.report(done(4)), Err(ReportError::NotItsJob(4)));
        assert_eq!(r.report(Report::Ready), Err(ReportError::JobLost(3)));
        assert_eq!(r.report(done(3)), Ok(Some(3)));
    }

    #[test]
    fn messages_round_trip() {
        for job in [
            cold(0),
            Job {
                partition: MAX_PARTITIONS - 1,
                kind: Kind::Warm,
                condition: StartCondition::PartitionRestart,
                restarts: u32::MAX,
                kill: Some(u64::MAX),
            },
        ] {
            assert_eq!(Job::from_words(job.to_words()), Some(job));
        }
        assert_eq!(Job::from_words([0, 0, 0]), None, "no kind");
        assert_eq!(
            Job::from_words([MAX_PARTITIONS as u64 | 1 << 8, 1, 0]),
            None
        );
        assert_eq!(
            Job::from_words([1 << 8 | 9 << 16, 1, 0]),
            None,
            "no condition"
        );
        assert_eq!(
            Job::from_words([1 << 8, 1 << 32, 0]),
            None,
            "too many restarts"
        );
        for report in [Report::Ready, done(5), Report::Failed { partition: 14 }] {
            let (label, words) = report.encode();
            assert_eq!(Report::decode(label, words), Some(report));
        }
        assert_eq!(Report::decode(0, [0; 3]), None);
    }

    proptest! {
        /// Any sequence of restarts and worker calls: jobs come out in the order they went in
        /// (each partition once), the worker never holds two, and nothing is lost.
        #[test]
        fn jobs_run_in_order(steps in proptest::collection::vec((0usize..MAX_PARTITIONS, any::<bool>()), 0..200)) {
            let mut r = Restarts::new();
            let mut model: std::collections::VecDeque<usize> = Default::default();
            let mut running: Option<usize> = None;
            let mut waiting = false;
            for (partition, is_push) in steps {
                if is_push {
                    let fresh = running != Some(partition) && !model.contains(&partition);
                    prop_assert_eq!(r.push(cold(partition)), fresh);
                    if fresh {
                        model.push_back(partition);
                    }
                } else if !waiting {
                    let report = running.map_or(Report::Ready, done);
                    prop_assert_eq!(r.report(report), Ok(running));
                    running = None;
                    waiting = true;
                }
                if waiting && let Some(next) = model.pop_front() {
                    prop_assert_eq!(r.dispatch().map(|j| j.partition), Some(next));
                    running = Some(next);
                    waiting = false;
                } else {
                    prop_assert_eq!(r.dispatch(), None);
                }
                prop_assert_eq!(r.waiting(), model.len());
            }
        }
    }
}
