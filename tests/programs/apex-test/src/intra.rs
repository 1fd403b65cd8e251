//! Partition `intra` (scenario `apex_intra`): the intra-partition services through the
//! a653rs basic traits. Three workers of priorities 10 (`w1`), 30 (`w2`) and 20 (`w3`)
//! each wait on their own gate semaphore; the driver (priority 5, below them all) sets a
//! phase and opens the gates in the order w1, w2, w3, so each worker runs at once and
//! waits on the phase's object: the arrival order is w1, w2, w3, the priority order w2,
//! w3, w1. The driver then signals / sends / displays / sets / releases, and the workers
//! note (in a log the driver prints) who got what in which order.
//!
//! Every line starts with `intra:`.

use apex::Warden;
use apex::a653rs::bindings::{
    self as b, ApexBlackboardP1, ApexBufferP1, ApexErrorP4, ApexEventP1, ApexMutexP1,
    ApexProcessP1, ApexSemaphoreP1, ApexTimeP1, ApexTimeP4, ErrorReturnCode, QueuingDiscipline,
};
use apex::a653rs::prelude::StartContext;
use apex::codes::apex_name;
use apex::user_rt::println;
use core::sync::atomic::{AtomicU8, AtomicU32, AtomicUsize, Ordering};

const MS: i64 = 1_000_000;
const INFINITE: i64 = b::INFINITE_TIME_VALUE;
const WORKERS: [(&str, i32); 3] = [("w1", 10), ("w2", 30), ("w3", 20)];
const DRIVER_PRIORITY: i32 = 5;
const CEILING: i32 = 60;
/// The driver's priority while a worker owns a mutex (which it may not wait in).
const ABOVE_CEILING: i32 = 70;

const SEM_FIFO: u32 = 1;
const SEM_PRIORITY: u32 = 2;
const BUF_FIFO: u32 = 3;
const BUF_PRIORITY: u32 = 4;
const BUF_SEND: u32 = 5;
const BLACKBOARD: u32 = 6;
const EVENT: u32 = 7;
const MUTEX_FIFO: u32 = 8;
const MUTEX_PRIORITY: u32 = 9;
const HOLD: u32 = 10;

static PHASE: AtomicU32 = AtomicU32::new(0);
static LOG: [AtomicU8; 96] = [const { AtomicU8::new(0) }; 96];
static LOG_LEN: AtomicUsize = AtomicUsize::new(0);

fn note(bytes: &[u8]) {
    for &byte in bytes {
        let at = LOG_LEN.fetch_add(1, Ordering::Relaxed);
        if at < LOG.len() {
            LOG[at].store(byte, Ordering::Relaxed);
        }
    }
}

/// Prints `intra: <what> <log>` and empties the log.
fn print_log(what: &str) {
    let length = LOG_LEN.swap(0, Ordering::Relaxed).min(LOG.len());
    let mut text = [0u8; 96];
    for (i, byte) in text.iter_mut().enumerate().take(length) {
        *byte = LOG[i].load(Ordering::Relaxed);
    }
    let text = core::str::from_utf8(&text[..length]).unwrap_or("?");
    match text.trim_end() {
        "" => println!("intra: {what}"),
        text => println!("intra: {what} {text}"),
    }
}

fn code<T>(result: Result<T, ErrorReturnCode>) -> Option<ErrorReturnCode> {
    result.err()
}

fn sem(name: &str) -> b::SemaphoreId {
    <Warden as ApexSemaphoreP1>::get_semaphore_id(apex_name(name)).expect("semaphore")
}
fn buf(name: &str) -> b::BufferId {
    <Warden as ApexBufferP1>::get_buffer_id(apex_name(name)).expect("buffer")
}
fn mutex(name: &str) -> b::MutexId {
    <Warden as ApexMutexP1>::get_mutex_id(apex_name(name)).expect("mutex")
}
fn bb() -> b::BlackboardId {
    <Warden as ApexBlackboardP1>::get_blackboard_id(apex_name("board")).expect("blackboard")
}
fn ev() -> b::EventId {
    <Warden as ApexEventP1>::get_event_id(apex_name("ev")).expect("event")
}
fn process_id(name: &str) -> b::ProcessId {
    <Warden as ApexProcessP1>::get_process_id(apex_name(name)).expect("process")
}
/// RECEIVE_BUFFER into `out`.
pub(crate) fn receive(
    id: b::BufferId,
    timeout: i64,
    out: &mut [u8],
) -> Result<u32, ErrorReturnCode> {
    #[allow(unsafe_code)]
    // SAFETY: a653rs's contract only asks for a writable slice, which `out` is; every
    // caller passes at least the buffer's message size.
    unsafe {
        <Warden as ApexBufferP1>::receive_buffer(id, timeout, out)
    }
}

/// READ_BLACKBOARD into `out`.
pub(crate) fn read(
    id: b::BlackboardId,
    timeout: i64,
    out: &mut [u8],
) -> Result<u32, ErrorReturnCode> {
    #[allow(unsafe_code)]
    // SAFETY: as for `receive`.
    unsafe {
        <Warden as ApexBlackboardP1>::read_blackboard(id, timeout, out)
    }
}

fn current_priority(id: b::ProcessId) -> i32 {
    <Warden as ApexProcessP1>::get_process_status(id).map_or(-1, |s| s.current_priority)
}
fn now() -> i64 {
    <Warden as ApexTimeP4>::get_time()
}
fn sleep(ms: i64) {
    let _ = <Warden as ApexTimeP1>::timed_wait(ms * MS);
}

/// Initialisation: the objects, the INIT-mode return codes, the processes.
pub fn create(_ctx: &mut StartContext<Warden>) {
    use QueuingDiscipline::{Fifo, Priority};
    let s = |name: &str, value, max, qd| {
        <Warden as ApexSemaphoreP1>::create_semaphore(apex_name(name), value, max, qd)
    };
    s("sem_fifo", 0, 3, Fifo).expect("sem_fifo");
    s("sem_prio", 0, 3, Priority).expect("sem_prio");
    for gate in ["gate1", "gate2", "gate3"] {
        s(gate, 0, 1, Fifo).expect("gate");
    }
    println!(
        "intra: init CREATE_SEMAPHORE again: {:?}",
        code(s("sem_fifo", 0, 3, Fifo))
    );
    println!(
        "intra: init CREATE_SEMAPHORE 4 of 3: {:?}",
        code(s("bad", 4, 3, Fifo))
    );
    let bf = |name: &str, qd| <Warden as ApexBufferP1>::create_buffer(apex_name(name), 4, 2, qd);
    bf("buf_fifo", Fifo).expect("buf_fifo");
    bf("buf_prio", Priority).expect("buf_prio");
    <Warden as ApexBlackboardP1>::create_blackboard(apex_name("board"), 8).expect("board");
    <Warden as ApexEventP1>::create_event(apex_name("ev")).expect("ev");
    let m = |name: &str, priority, qd| {
        <Warden as ApexMutexP1>::create_mutex(apex_name(name), priority, qd)
    };
    m("mtx_fifo", CEILING, Fifo).expect("mtx_fifo");
    m("mtx_prio", CEILING, Priority).expect("mtx_prio");
    m("mtx_low", 3, Fifo).expect("mtx_low");
    println!(
        "intra: init CREATE_MUTEX at the MCP: {:?}",
        code(m("mtx_top", 100, Fifo))
    );
    let mut made = 3;
    let refused = loop {
        let name = [b'm', b'0' + made];
        match m(core::str::from_utf8(&name).unwrap_or("m"), 50, Fifo) {
            Ok(_) => made += 1,
            Err(e) => break e,
        }
    };
    println!("intra: init {made} mutexes, then CREATE_MUTEX: {refused:?}");
    println!(
        "intra: init WAIT_SEMAPHORE 5 ms outside a process: {:?}",
        code(<Warden as ApexSemaphoreP1>::wait_semaphore(
            sem("sem_fifo"),
            5 * MS
        ))
    );
    crate::start_aperiodic("driver", driver, DRIVER_PRIORITY);
    for (name, priority) in WORKERS {
        crate::start_aperiodic(name, worker, priority);
    }
}

fn my_index() -> usize {
    let me = <Warden as ApexProcessP1>::get_my_id().expect("a process");
    WORKERS
        .iter()
        .position(|(name, _)| process_id(name) == me)
        .expect("a worker")
}

extern "C" fn worker() {
    let index = my_index();
    let digit = b'1' + index as u8;
    let gate = sem(["gate1", "gate2", "gate3"][index]);
    let me = process_id(WORKERS[index].0);
    let mut message = [0u8; 8];
    loop {
        <Warden as ApexSemaphoreP1>::wait_semaphore(gate, INFINITE).expect("gate");
        let phase = PHASE.load(Ordering::Relaxed);
        // The FIFO phases wait for ever, the PRIORITY ones with a finite time-out.
        let result = match phase {
            SEM_FIFO | SEM_PRIORITY => {
                let (name, timeout) = if phase == SEM_FIFO {
                    ("sem_fifo", INFINITE)
                } else {
                    ("sem_prio", 500 * MS)
                };
                <Warden as ApexSemaphoreP1>::wait_semaphore(sem(name), timeout).map(|()| None)
            }
            BUF_FIFO | BUF_PRIORITY => {
                let (name, timeout) = if phase == BUF_FIFO {
                    ("buf_fifo", INFINITE)
                } else {
                    ("buf_prio", 500 * MS)
                };
                receive(buf(name), timeout, &mut message)
                    .map(|n| Some(message[..n as usize].first().copied().unwrap_or(b'?')))
            }
            BUF_SEND => <Warden as ApexBufferP1>::send_buffer(buf("buf_prio"), &[digit], 500 * MS)
                .map(|()| Some(b's')),
            BLACKBOARD => read(bb(), INFINITE, &mut message).map(|_| Some(message[0])),
            EVENT => <Warden as ApexEventP1>::wait_event(ev(), 500 * MS).map(|()| None),
            MUTEX_FIFO | MUTEX_PRIORITY => {
                let id = mutex(if phase == MUTEX_FIFO {
                    "mtx_fifo"
                } else {
                    "mtx_prio"
                });
                let got = <Warden as ApexMutexP1>::acquire_mutex(id, INFINITE);
                if got.is_ok() {
                    let priority = current_priority(me);
                    note(&[
                        digit,
                        b'@',
                        b'0' + (priority / 10) as u8,
                        b'0' + (priority % 10) as u8,
                        b' ',
                    ]);
                    <Warden as ApexMutexP1>::release_mutex(id).expect("RELEASE_MUTEX");
                }
                got.map(|()| Some(0))
            }
            HOLD => {
                let id = mutex("mtx_fifo");
                <Warden as ApexMutexP1>::acquire_mutex(id, 0).expect("ACQUIRE_MUTEX");
                let waited = <Warden as ApexSemaphoreP1>::wait_semaphore(gate, INFINITE);
                println!(
                    "intra: w3 owns mtx_fifo at priority {}; WAIT_SEMAPHORE while owning it: {:?}",
                    current_priority(me),
                    code(waited)
                );
                println!(
                    "intra: w3 owning it: TIMED_WAIT {:?}, SUSPEND_SELF {:?}",
                    code(<Warden as ApexTimeP1>::timed_wait(MS)),
                    code(<Warden as ApexProcessP1>::suspend_self(5 * MS))
                );
                // It may not wait, so it runs on (at the ceiling) until the driver, above
                // the ceiling, has reset the mutex.
                while <Warden as ApexMutexP1>::get_process_mutex_state(me) == Ok(id) {
                    core::hint::spin_loop();
                }
                let released = <Warden as ApexMutexP1>::release_mutex(id);
                println!(
                    "intra: w3 after the reset: RELEASE_MUTEX {:?}, priority {}",
                    code(released),
                    current_priority(me)
                );
                Ok(Some(0))
            }
            _ => Ok(None),
        };
        match result {
            Ok(Some(0)) => {}
            Ok(Some(byte)) => note(&[digit, byte, b' ']),
            Ok(None) => note(&[digit, b' ']),
            Err(e) => println!("intra: w{} phase {phase}: {e:?}", index + 1),
        }
    }
}

/// Opens the gates in the order w1, w2, w3 (each worker runs and waits on the phase's
/// object before the next gate opens); `pause` when the driver runs above the workers.
fn arrive(phase: u32, pause: bool) {
    PHASE.store(phase, Ordering::Relaxed);
    for gate in ["gate1", "gate2", "gate3"] {
        <Warden as ApexSemaphoreP1>::signal_semaphore(sem(gate)).expect("gate");
        if pause {
            sleep(5);
        }
    }
}

fn waiting_sem(name: &str) -> i32 {
    <Warden as ApexSemaphoreP1>::get_semaphore_status(sem(name)).map_or(-1, |s| s.waiting_processes)
}

extern "C" fn driver() {
    // ---- wake order: semaphores
    for (phase, name, what) in [
        (SEM_FIFO, "sem_fifo", "FIFO"),
        (SEM_PRIORITY, "sem_prio", "PRIORITY"),
    ] {
        arrive(phase, false);
        let waiting = waiting_sem(name);
        for _ in 0..3 {
            <Warden as ApexSemaphoreP1>::signal_semaphore(sem(name)).expect("SIGNAL_SEMAPHORE");
        }
        print_log(&alloc_free_label(&[
            "semaphore ",
            what,
            " waiting ",
            digits(waiting),
            " woken",
        ]));
    }

    // ---- buffers: receivers wait, then senders wait
    for (phase, name, what) in [
        (BUF_FIFO, "buf_fifo", "FIFO"),
        (BUF_PRIORITY, "buf_prio", "PRIORITY"),
    ] {
        arrive(phase, false);
        for message in [b"a", b"b", b"c"] {
            <Warden as ApexBufferP1>::send_buffer(buf(name), message, 0).expect("SEND_BUFFER");
        }
        print_log(&alloc_free_label(&["buffer ", what, " receivers got"]));
    }
    let id = buf("buf_prio");
    for message in [b"x", b"y"] {
        <Warden as ApexBufferP1>::send_buffer(id, message, 0).expect("SEND_BUFFER");
    }
    arrive(BUF_SEND, false);
    let waiting =
        <Warden as ApexBufferP1>::get_buffer_status(id).map_or(-1, |s| s.waiting_processes);
    let mut got = [b' '; 10];
    let mut message = [0u8; 4];
    for i in 0..5 {
        let n = receive(id, 0, &mut message);
        got[2 * i] = if n.is_ok() { message[0] } else { b'-' };
    }
    print_log("buffer PRIORITY senders sent");
    println!(
        "intra: buffer PRIORITY {waiting} senders waited, received {}",
        core::str::from_utf8(&got).unwrap_or("?").trim_end()
    );

    // ---- blackboard and event: everybody wakes
    arrive(BLACKBOARD, false);
    let board = bb();
    let waiting = <Warden as ApexBlackboardP1>::get_blackboard_status(board)
        .map_or(-1, |s| s.waiting_processes);
    <Warden as ApexBlackboardP1>::display_blackboard(board, b"go").expect("DISPLAY_BLACKBOARD");
    print_log(&alloc_free_label(&[
        "DISPLAY_BLACKBOARD with ",
        digits(waiting),
        " waiting woke",
    ]));
    arrive(EVENT, false);
    let waiting =
        <Warden as ApexEventP1>::get_event_status(ev()).map_or(-1, |s| s.waiting_processes);
    <Warden as ApexEventP1>::set_event(ev()).expect("SET_EVENT");
    print_log(&alloc_free_label(&[
        "SET_EVENT with ",
        digits(waiting),
        " waiting woke",
    ]));
    <Warden as ApexEventP1>::reset_event(ev()).expect("RESET_EVENT");
    println!(
        "intra: after RESET_EVENT WAIT_EVENT 0: {:?}",
        code(<Warden as ApexEventP1>::wait_event(ev(), 0))
    );

    // ---- mutexes: priority ceiling. The owner runs at the ceiling (above the workers) and
    // may not wait, so on one core nobody ever waits for it: the workers readied meanwhile
    // take it in turn after the release, by priority (the wait queues' order is shown by
    // the host tests).
    let me = process_id("driver");
    for (phase, name, what) in [
        (MUTEX_PRIORITY, "mtx_prio", "PRIORITY"),
        (MUTEX_FIFO, "mtx_fifo", "FIFO"),
    ] {
        let id = mutex(name);
        <Warden as ApexMutexP1>::acquire_mutex(id, INFINITE).expect("ACQUIRE_MUTEX");
        let raised = current_priority(me);
        arrive(phase, false);
        let waiting =
            <Warden as ApexMutexP1>::get_mutex_status(id).map_or(-1, |s| s.waiting_processes);
        <Warden as ApexMutexP1>::release_mutex(id).expect("RELEASE_MUTEX");
        println!(
            "intra: mutex {what}: the driver ran at {raised}, back at {}, {waiting} waiting",
            current_priority(me)
        );
        print_log(&alloc_free_label(&["mutex ", what, " owners"]));
    }
    println!(
        "intra: worker priorities after the mutexes: {} {} {}",
        current_priority(process_id("w1")),
        current_priority(process_id("w2")),
        current_priority(process_id("w3"))
    );

    // ---- a mutex owned by another: status, SUSPEND, RESET_MUTEX. Its owner w3 may not
    // wait, so the driver runs above the ceiling to preempt it (and cannot take it there).
    let id = mutex("mtx_fifo");
    <Warden as ApexProcessP1>::set_priority(me, ABOVE_CEILING).expect("SET_PRIORITY");
    PHASE.store(HOLD, Ordering::Relaxed);
    <Warden as ApexSemaphoreP1>::signal_semaphore(sem("gate3")).expect("gate3");
    sleep(5);
    let w3 = process_id("w3");
    println!(
        "intra: SUSPEND of the owner w3: {:?}",
        code(<Warden as ApexProcessP1>::suspend(w3))
    );
    let owner = <Warden as ApexMutexP1>::get_process_mutex_state(w3) == Ok(id);
    let status = <Warden as ApexMutexP1>::get_mutex_status(id).expect("GET_MUTEX_STATUS");
    println!(
        "intra: GET_PROCESS_MUTEX_STATE(w3) is mtx_fifo: {owner}; status owner w3: {} {:?} lock count {} priority {}",
        status.mutex_owner == w3,
        status.mutex_state,
        status.lock_count,
        status.mutex_priority
    );
    println!(
        "intra: RELEASE_MUTEX not owner: {:?}; RESET_MUTEX(w3): {:?}; then {:?}, w3 at priority {}",
        code(<Warden as ApexMutexP1>::release_mutex(id)),
        code(<Warden as ApexMutexP1>::reset_mutex(id, w3)),
        <Warden as ApexMutexP1>::get_mutex_status(id).map(|s| s.mutex_state),
        current_priority(w3)
    );
    <Warden as ApexProcessP1>::set_priority(me, DRIVER_PRIORITY).expect("SET_PRIORITY");
    sleep(40);

    // ---- time-outs
    let t = |f: &dyn Fn() -> Option<ErrorReturnCode>, ms: i64| {
        let start = now();
        let e = f();
        (e, now() - start >= ms * MS)
    };
    let s = sem("sem_fifo");
    println!(
        "intra: WAIT_SEMAPHORE 0: {:?}; 10 ms: {:?}; waiting after: {}",
        code(<Warden as ApexSemaphoreP1>::wait_semaphore(s, 0)),
        t(
            &|| code(<Warden as ApexSemaphoreP1>::wait_semaphore(s, 10 * MS)),
            10
        ),
        waiting_sem("sem_fifo")
    );
    let f = buf("buf_fifo");
    let mut message = [0u8; 4];
    let empty = t(&|| code(receive(f, 5 * MS, &mut [0u8; 4])), 5);
    let empty0 = code(receive(f, 0, &mut message));
    for m in [b"1", b"2"] {
        <Warden as ApexBufferP1>::send_buffer(f, m, 0).expect("SEND_BUFFER");
    }
    println!(
        "intra: RECEIVE_BUFFER empty 0: {empty0:?}; 5 ms: {empty:?}; SEND_BUFFER full 0: {:?}; 5 ms: {:?}",
        code(<Warden as ApexBufferP1>::send_buffer(f, b"3", 0)),
        t(
            &|| code(<Warden as ApexBufferP1>::send_buffer(f, b"3", 5 * MS)),
            5
        )
    );
    <Warden as ApexBlackboardP1>::clear_blackboard(board).expect("CLEAR_BLACKBOARD");
    let mut text = [0u8; 8];
    let read0 = code(read(board, 0, &mut text));
    let read5 = t(&|| code(read(board, 5 * MS, &mut [0u8; 8])), 5);
    println!(
        "intra: READ_BLACKBOARD cleared 0: {read0:?}; 5 ms: {read5:?}; WAIT_EVENT 5 ms: {:?}",
        t(
            &|| code(<Warden as ApexEventP1>::wait_event(ev(), 5 * MS)),
            5
        )
    );

    // ---- return codes in NORMAL mode
    let qd = QueuingDiscipline::Fifo;
    println!(
        "intra: CREATE in NORMAL: {:?} {:?} {:?} {:?} {:?}",
        code(<Warden as ApexBufferP1>::create_buffer(
            apex_name("late"),
            4,
            2,
            qd
        )),
        code(<Warden as ApexBlackboardP1>::create_blackboard(
            apex_name("late"),
            4
        )),
        code(<Warden as ApexSemaphoreP1>::create_semaphore(
            apex_name("late"),
            0,
            1,
            qd
        )),
        code(<Warden as ApexEventP1>::create_event(apex_name("late"))),
        code(<Warden as ApexMutexP1>::create_mutex(
            apex_name("late"),
            50,
            qd
        )),
    );
    <Warden as ApexSemaphoreP1>::signal_semaphore(s).expect("SIGNAL_SEMAPHORE");
    for _ in 0..2 {
        <Warden as ApexSemaphoreP1>::signal_semaphore(s).expect("SIGNAL_SEMAPHORE");
    }
    println!(
        "intra: SIGNAL_SEMAPHORE at its maximum: {:?}; SEND_BUFFER too long: {:?}; DISPLAY_BLACKBOARD too long: {:?}",
        code(<Warden as ApexSemaphoreP1>::signal_semaphore(s)),
        code(<Warden as ApexBufferP1>::send_buffer(
            buf("buf_prio"),
            b"12345",
            0
        )),
        code(<Warden as ApexBlackboardP1>::display_blackboard(
            board,
            b"123456789"
        )),
    );
    println!(
        "intra: unknown ids: {:?} {:?} {:?} {:?} {:?}",
        code(<Warden as ApexBufferP1>::get_buffer_status(9999)),
        code(<Warden as ApexBlackboardP1>::get_blackboard_status(9999)),
        code(<Warden as ApexSemaphoreP1>::get_semaphore_status(9999)),
        code(<Warden as ApexEventP1>::get_event_status(9999)),
        code(<Warden as ApexMutexP1>::get_mutex_status(9999)),
    );
    println!(
        "intra: unknown names: {:?} {:?} {:?} {:?} {:?}",
        code(<Warden as ApexBufferP1>::get_buffer_id(apex_name(
            "nonesuch"
        ))),
        code(<Warden as ApexBlackboardP1>::get_blackboard_id(apex_name(
            "nonesuch"
        ))),
        code(<Warden as ApexSemaphoreP1>::get_semaphore_id(apex_name(
            "nonesuch"
        ))),
        code(<Warden as ApexEventP1>::get_event_id(apex_name("nonesuch"))),
        code(<Warden as ApexMutexP1>::get_mutex_id(apex_name("nonesuch"))),
    );
    println!(
        "intra: ACQUIRE_MUTEX above its ceiling: {:?}; RELEASE_MUTEX not owned: {:?}",
        code(<Warden as ApexMutexP1>::acquire_mutex(mutex("mtx_low"), 0)),
        code(<Warden as ApexMutexP1>::release_mutex(mutex("mtx_prio"))),
    );

    println!(
        "intra: unknown process: RESET_MUTEX {:?}; GET_PROCESS_MUTEX_STATE {:?}; driver owns {}",
        code(<Warden as ApexMutexP1>::reset_mutex(mutex("mtx_prio"), 999)),
        code(<Warden as ApexMutexP1>::get_process_mutex_state(999)),
        <Warden as ApexMutexP1>::get_process_mutex_state(me).unwrap_or(0),
    );

    // ---- a stopped waiter leaves the queue
    let s = sem("sem_prio");
    PHASE.store(SEM_PRIORITY, Ordering::Relaxed);
    <Warden as ApexSemaphoreP1>::signal_semaphore(sem("gate1")).expect("gate1");
    let before = waiting_sem("sem_prio");
    <Warden as ApexProcessP1>::stop(process_id("w1")).expect("STOP");
    let after = waiting_sem("sem_prio");
    <Warden as ApexSemaphoreP1>::signal_semaphore(s).expect("SIGNAL_SEMAPHORE");
    println!(
        "intra: STOP of a waiter: waiting {before} -> {after}; SIGNAL_SEMAPHORE then leaves {}",
        <Warden as ApexSemaphoreP1>::get_semaphore_status(s).map_or(-1, |s| s.current_value)
    );
    // ---- a SUSPENDed waiter: the wake is decided, it goes on when RESUMEd
    PHASE.store(EVENT, Ordering::Relaxed);
    <Warden as ApexSemaphoreP1>::signal_semaphore(sem("gate2")).expect("gate2");
    let w2 = process_id("w2");
    <Warden as ApexProcessP1>::suspend(w2).expect("SUSPEND");
    <Warden as ApexEventP1>::set_event(ev()).expect("SET_EVENT");
    let waiting =
        <Warden as ApexEventP1>::get_event_status(ev()).map_or(-1, |s| s.waiting_processes);
    sleep(5);
    print_log("SUSPENDed waiter after SET_EVENT: woke");
    let state = <Warden as ApexProcessP1>::get_process_status(w2).map(|s| s.process_state);
    <Warden as ApexProcessP1>::resume(w2).expect("RESUME");
    println!("intra: SUSPENDed waiter: {waiting} waiting after SET_EVENT, state {state:?}");
    print_log("SUSPENDed waiter after RESUME: woke");
    <Warden as ApexEventP1>::reset_event(ev()).expect("RESET_EVENT");
    println!("intra: done");
    let _ = <Warden as ApexErrorP4>::raise_application_error(
        b::ErrorCode::ApplicationError,
        b"intra done",
    );
}

/// `value` as decimal text (0..=99) in a static-free way.
fn digits(value: i32) -> &'static str {
    const D: [&str; 10] = ["0", "1", "2", "3", "4", "5", "6", "7", "8", "9"];
    D.get(value as usize).copied().unwrap_or("?")
}

/// Joins `parts` into a fixed buffer (no allocation).
fn alloc_free_label(parts: &[&str]) -> Label {
    let mut label = Label([0; 64], 0);
    for part in parts {
        for &byte in part.as_bytes() {
            if label.1 < label.0.len() {
                label.0[label.1] = byte;
                label.1 += 1;
            }
        }
    }
    label
}

struct Label([u8; 64], usize);

impl core::ops::Deref for Label {
    type Target = str;
    fn deref(&self) -> &str {
        core::str::from_utf8(&self.0[..self.1]).unwrap_or("?")
    }
}
