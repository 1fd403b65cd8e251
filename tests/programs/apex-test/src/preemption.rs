//! Partition `preempt` (scenario `apex_preemption`): LOCK_PREEMPTION / UNLOCK_PREEMPTION
//! through the a653rs basic traits. `holder` (priority 10) locks preemption and then
//! readies `rival` (priority 50, waiting on a semaphore): the rival runs only when the
//! lock level is back at 0. Meanwhile the holder sees the codes of the services a lock
//! owner may not call, the lock level up to MAX_LOCK_LEVEL and beyond, and a SET_PRIORITY
//! of itself that takes effect at the unlock.
//!
//! Every line starts with `preempt:`.

use apex::Warden;
use apex::a653rs::bindings::{
    self as b, ApexErrorP4, ApexMutexP1, ApexPartitionP4, ApexProcessP1, ApexSemaphoreP1,
    ApexTimeP1, ApexTimeP4, ErrorReturnCode, QueuingDiscipline,
};
use apex::a653rs::prelude::StartContext;
use apex::codes::apex_name;
use apex::user_rt::println;
use core::sync::atomic::{AtomicU32, Ordering};

const MS: i64 = 1_000_000;
const INFINITE: i64 = b::INFINITE_TIME_VALUE;
const HOLDER_PRIORITY: i32 = 10;
const RIVAL_PRIORITY: i32 = 50;

/// How often the rival has run (after its wake-up).
static RIVAL_RAN: AtomicU32 = AtomicU32::new(0);

fn code<T>(result: Result<T, ErrorReturnCode>) -> Option<ErrorReturnCode> {
    result.err()
}

fn sem(name: &str) -> b::SemaphoreId {
    <Warden as ApexSemaphoreP1>::get_semaphore_id(apex_name(name)).expect("semaphore")
}

fn lock() -> Result<b::LockLevel, ErrorReturnCode> {
    <Warden as ApexProcessP1>::lock_preemption()
}

fn unlock() -> Result<b::LockLevel, ErrorReturnCode> {
    <Warden as ApexProcessP1>::unlock_preemption()
}

fn now() -> i64 {
    <Warden as ApexTimeP4>::get_time()
}

fn current_priority() -> i32 {
    let me = <Warden as ApexProcessP1>::get_my_id().expect("a process");
    <Warden as ApexProcessP1>::get_process_status(me).map_or(-1, |s| s.current_priority)
}

/// Initialisation: LOCK_PREEMPTION outside NORMAL mode, the objects, the processes.
pub fn create(_ctx: &mut StartContext<Warden>) {
    println!("preempt: init LOCK_PREEMPTION: {:?}", code(lock()));
    let s = |name: &str| {
        <Warden as ApexSemaphoreP1>::create_semaphore(
            apex_name(name),
            0,
            1,
            QueuingDiscipline::Fifo,
        )
    };
    s("wake").expect("wake");
    s("never").expect("never");
    <Warden as ApexMutexP1>::create_mutex(apex_name("mtx"), 60, QueuingDiscipline::Fifo)
        .expect("mtx");
    crate::start_aperiodic("rival", rival, RIVAL_PRIORITY);
    crate::start_aperiodic("holder", holder, HOLDER_PRIORITY);
}

extern "C" fn rival() {
    loop {
        <Warden as ApexSemaphoreP1>::wait_semaphore(sem("wake"), INFINITE).expect("wake");
        RIVAL_RAN.fetch_add(1, Ordering::Relaxed);
    }
}

extern "C" fn holder() {
    let first = lock();
    let second = lock();
    let status = <Warden as ApexPartitionP4>::get_partition_status();
    println!(
        "preempt: LOCK_PREEMPTION {first:?} {second:?}; partition lock level {}; priority {}",
        status.lock_level,
        current_priority()
    );
    // The rival is ready now and above the holder's own priority, but must not run.
    <Warden as ApexSemaphoreP1>::signal_semaphore(sem("wake")).expect("SIGNAL_SEMAPHORE");
    let until = now() + 3 * MS;
    while now() < until {
        core::hint::spin_loop();
    }
    println!(
        "preempt: rival readied, 3 ms later it ran {} times",
        RIVAL_RAN.load(Ordering::Relaxed)
    );

    // What a lock owner may not do.
    let me = <Warden as ApexProcessP1>::get_my_id().expect("a process");
    println!(
        "preempt: locked: TIMED_WAIT {:?}; WAIT_SEMAPHORE 5 ms {:?}, 0 {:?}; SUSPEND_SELF 5 ms {:?}; ACQUIRE_MUTEX {:?}; GET_PROCESS_MUTEX_STATE is PREEMPTION_LOCK_MUTEX: {}",
        code(<Warden as ApexTimeP1>::timed_wait(MS)),
        code(<Warden as ApexSemaphoreP1>::wait_semaphore(
            sem("never"),
            5 * MS
        )),
        code(<Warden as ApexSemaphoreP1>::wait_semaphore(sem("never"), 0)),
        code(<Warden as ApexProcessP1>::suspend_self(5 * MS)),
        code(<Warden as ApexMutexP1>::acquire_mutex(
            <Warden as ApexMutexP1>::get_mutex_id(apex_name("mtx")).expect("mtx"),
            0
        )),
        <Warden as ApexMutexP1>::get_process_mutex_state(me) == Ok(b::PREEMPTION_LOCK_MUTEX),
    );

    // Up to MAX_LOCK_LEVEL, then INVALID_CONFIG.
    let mut level = second.unwrap_or(0);
    while let Ok(next) = lock() {
        level = next;
    }
    println!(
        "preempt: locked up to {level} (MAX_LOCK_LEVEL {}), then {:?}",
        b::MAX_LOCK_LEVEL,
        code(lock())
    );
    // SET_PRIORITY of itself takes effect at the unlock.
    <Warden as ApexProcessP1>::set_priority(me, 20).expect("SET_PRIORITY");
    let locked_priority = current_priority();
    while level > 1 {
        level = unlock().expect("UNLOCK_PREEMPTION");
    }
    println!(
        "preempt: unlocked to 1: rival ran {} times, priority {locked_priority}",
        RIVAL_RAN.load(Ordering::Relaxed)
    );
    let last = unlock();
    // The rival, above the holder's priority 20, ran inside the last unlock.
    println!(
        "preempt: UNLOCK_PREEMPTION {last:?}: rival ran {} times, priority {}; again {:?}",
        RIVAL_RAN.load(Ordering::Relaxed),
        current_priority(),
        code(unlock())
    );
    println!(
        "preempt: unlocked: TIMED_WAIT 1 ms {:?}",
        code(<Warden as ApexTimeP1>::timed_wait(MS))
    );
    println!("preempt: done");
    let _ = <Warden as ApexErrorP4>::raise_application_error(
        b::ErrorCode::ApplicationError,
        b"preempt done",
    );
}
