//! Every return code of every intra-partition service, both queuing disciplines, time-outs,
//! wake order and the mutex priority ceiling.

use super::*;
use crate::codes::apex_name;
use ErrorReturnCode::*;
use QueuingDiscipline::{Fifo, Priority as Prio};

extern crate std;
use std::boxed::Box;

const MCP: u8 = 100;
const INFINITE: ApexSystemTime = INFINITE_TIME_VALUE;
const FINITE: ApexSystemTime = 5_000_000;

fn intra() -> Box<Intra> {
    let mut i = Box::new(Intra::EMPTY);
    i.reset();
    i
}

fn p(slot: usize, priority: u8) -> Caller {
    Caller::process(slot, priority)
}

const INIT: Caller = Caller {
    slot: None,
    priority: 1,
};

fn n(text: &str) -> ApexName {
    apex_name(text)
}

fn done<T>(step: Result<Step<T>>) -> Result<T> {
    match step? {
        Step::Done(r) => Ok(r),
        Step::Wait => panic!("the service waits"),
    }
}

fn waits<T: core::fmt::Debug + PartialEq>(step: Result<Step<T>>) {
    assert_eq!(step, Ok(Step::Wait));
}

/// The order in which `slots` were woken, by taking each one's outcome (`end_wait`).
fn woken(i: &mut Intra) -> u32 {
    i.take_woken()
}

// ---------------------------------------------------------------- buffers

#[test]
fn create_buffer_codes() {
    let mut i = intra();
    let id = i.create_buffer(false, n("b"), 16, 4, Fifo).unwrap();
    assert_eq!(i.create_buffer(false, n("b"), 16, 4, Fifo), Err(NoAction));
    assert_eq!(
        i.create_buffer(false, n("z"), 0, 4, Fifo),
        Err(InvalidParam)
    );
    assert_eq!(
        i.create_buffer(false, n("z"), MAX_MESSAGE_SIZE as u32 + 1, 4, Fifo),
        Err(InvalidParam)
    );
    assert_eq!(
        i.create_buffer(false, n("z"), 16, 0, Fifo),
        Err(InvalidParam)
    );
    assert_eq!(
        i.create_buffer(false, n("z"), 16, MAX_BUFFER_MESSAGES as u32 + 1, Fifo),
        Err(InvalidParam)
    );
    assert_eq!(i.create_buffer(true, n("z"), 16, 4, Fifo), Err(InvalidMode));
    assert_eq!(i.get_buffer_id(&n("b")), Ok(id));
    assert_eq!(i.get_buffer_id(&n("nope")), Err(InvalidConfig));
    for k in 1..MAX_BUFFERS {
        i.create_buffer(false, n(&std::format!("b{k}")), 8, 2, Prio)
            .unwrap();
    }
    assert_eq!(
        i.create_buffer(false, n("z"), 16, 4, Fifo),
        Err(InvalidConfig)
    );
}

#[test]
fn buffer_pool_is_bounded() {
    let mut i = intra();
    // 128 messages of 256 bytes need 128 * 258 bytes: once; the pool has 32 KiB.
    i.create_buffer(false, n("big"), 256, 100, Fifo).unwrap();
    assert_eq!(
        i.create_buffer(false, n("big2"), 256, 100, Fifo),
        Err(InvalidConfig)
    );
    assert_eq!(i.create_blackboard(false, n("bb"), 256).map(|_| ()), Ok(()));
}

#[test]
fn buffer_send_receive_fifo_order_and_codes() {
    let mut i = intra();
    let id = i.create_buffer(false, n("b"), 4, 2, Fifo).unwrap();
    let mut out = [0u8; 4];
    assert_eq!(
        done(i.send_buffer(p(0, 10), id + 1, b"x", 0)),
        Err(InvalidParam)
    );
    assert_eq!(done(i.send_buffer(p(0, 10), id, b"", 0)), Err(InvalidParam));
    assert_eq!(
        done(i.send_buffer(p(0, 10), id, b"12345", 0)),
        Err(InvalidParam)
    );
    assert_eq!(done(i.send_buffer(p(0, 10), id, b"a", 0)), Ok(()));
    assert_eq!(done(i.send_buffer(p(0, 10), id, b"bb", 0)), Ok(()));
    assert_eq!(
        done(i.send_buffer(p(0, 10), id, b"c", 0)),
        Err(NotAvailable)
    );
    // Full: a finite or infinite wait is refused where waiting is not allowed.
    assert_eq!(
        done(i.send_buffer(INIT, id, b"c", FINITE)),
        Err(InvalidMode)
    );
    assert_eq!(
        done(i.send_buffer(p(ERROR_HANDLER_SLOT, MCP), id, b"c", INFINITE)),
        Err(InvalidMode)
    );
    let status = i.get_buffer_status(id).unwrap();
    assert_eq!(
        (
            status.nb_message,
            status.max_nb_message,
            status.max_message_size
        ),
        (2, 2, 4)
    );
    assert_eq!(i.get_buffer_status(id + 1), Err(InvalidParam));
    let mut small = [0u8; 3];
    assert_eq!(
        done(i.receive_buffer(p(1, 10), id, 0, &mut small)),
        Err(InvalidParam)
    );
    assert_eq!(
        done(i.receive_buffer(p(1, 10), id + 7, 0, &mut out)),
        Err(InvalidParam)
    );
    assert_eq!(done(i.receive_buffer(p(1, 10), id, 0, &mut out)), Ok(1));
    assert_eq!(&out[..1], b"a");
    assert_eq!(done(i.receive_buffer(p(1, 10), id, 0, &mut out)), Ok(2));
    assert_eq!(&out[..2], b"bb");
    assert_eq!(
        done(i.receive_buffer(p(1, 10), id, 0, &mut out)),
        Err(NotAvailable)
    );
    assert_eq!(
        done(i.receive_buffer(INIT, id, INFINITE, &mut out)),
        Err(InvalidMode)
    );
    // The ring wraps.
    for round in 0..5u8 {
        assert_eq!(done(i.send_buffer(INIT, id, &[round], 0)), Ok(()));
        assert_eq!(done(i.receive_buffer(INIT, id, 0, &mut out)), Ok(1));
        assert_eq!(out[0], round);
    }
}

#[test]
fn buffer_receiver_waits_and_gets_the_message_directly() {
    for discipline in [Fifo, Prio] {
        let mut i = intra();
        let id = i.create_buffer(false, n("b"), 8, 1, discipline).unwrap();
        let mut out = [0u8; 8];
        waits(i.receive_buffer(p(0, 5), id, INFINITE, &mut out));
        waits(i.receive_buffer(p(1, 20), id, FINITE, &mut out));
        waits(i.receive_buffer(p(2, 20), id, FINITE, &mut out));
        assert_eq!(i.get_buffer_status(id).unwrap().waiting_processes, 3);
        assert_eq!(i.end_wait(1, false), None, "not woken yet");
        assert_eq!(done(i.send_buffer(p(3, 1), id, b"one", 0)), Ok(()));
        let first = if discipline == Fifo { 0 } else { 1 };
        assert_eq!(woken(&mut i), 1 << first);
        assert_eq!(i.end_wait(first, false), Some(Ok(3)));
        assert_eq!(i.mail(first), b"one");
        // The buffer stays empty: the message went to the receiver.
        assert_eq!(i.get_buffer_status(id).unwrap().nb_message, 0);
        assert_eq!(done(i.send_buffer(p(3, 1), id, b"two", 0)), Ok(()));
        let second = if discipline == Fifo { 1 } else { 2 };
        assert_eq!(woken(&mut i), 1 << second);
        assert_eq!(i.end_wait(second, true), Some(Ok(3)), "the wake wins");
        // The last one times out and leaves the queue.
        let last = 3 - first - second;
        assert_eq!(i.end_wait(last, true), Some(Err(TimedOut)));
        assert_eq!(i.get_buffer_status(id).unwrap().waiting_processes, 0);
        assert_eq!(done(i.send_buffer(p(3, 1), id, b"3", 0)), Ok(()));
        assert_eq!(woken(&mut i), 0);
        assert_eq!(i.get_buffer_status(id).unwrap().nb_message, 1);
    }
}

#[test]
fn buffer_sender_waits_for_room() {
    for discipline in [Fifo, Prio] {
        let mut i = intra();
        let id = i.create_buffer(false, n("b"), 8, 1, discipline).unwrap();
        let mut out = [0u8; 8];
        assert_eq!(done(i.send_buffer(p(0, 5), id, b"0", 0)), Ok(()));
        waits(i.send_buffer(p(1, 5), id, b"low", INFINITE));
        waits(i.send_buffer(p(2, 30), id, b"high", INFINITE));
        waits(i.send_buffer(p(3, 30), id, b"high2", FINITE));
        assert_eq!(done(i.receive_buffer(p(4, 1), id, 0, &mut out)), Ok(1));
        let order: [(usize, &[u8]); 3] = if discipline == Fifo {
            [(1, b"low"), (2, b"high"), (3, b"high2")]
        } else {
            [(2, b"high"), (3, b"high2"), (1, b"low")]
        };
        for (slot, message) in order {
            assert_eq!(woken(&mut i), 1 << slot);
            assert_eq!(i.end_wait(slot, false), Some(Ok(0)));
            let got = done(i.receive_buffer(p(4, 1), id, 0, &mut out)).unwrap();
            assert_eq!(&out[..got], message);
        }
        assert_eq!(
            done(i.receive_buffer(p(4, 1), id, 0, &mut out)),
            Err(NotAvailable)
        );
    }
}

#[test]
fn buffer_sender_time_out_drops_its_message() {
    let mut i = intra();
    let id = i.create_buffer(false, n("b"), 8, 1, Fifo).unwrap();
    let mut out = [0u8; 8];
    assert_eq!(done(i.send_buffer(p(0, 5), id, b"0", 0)), Ok(()));
    waits(i.send_buffer(p(1, 5), id, b"late", FINITE));
    assert_eq!(i.end_wait(1, true), Some(Err(TimedOut)));
    assert_eq!(done(i.receive_buffer(p(4, 1), id, 0, &mut out)), Ok(1));
    assert_eq!(woken(&mut i), 0);
    assert_eq!(
        done(i.receive_buffer(p(4, 1), id, 0, &mut out)),
        Err(NotAvailable)
    );
}

// ---------------------------------------------------------------- blackboards

#[test]
fn blackboard_codes() {
    let mut i = intra();
    let id = i.create_blackboard(false, n("bb"), 8).unwrap();
    assert_eq!(i.create_blackboard(false, n("bb"), 8), Err(NoAction));
    assert_eq!(i.create_blackboard(false, n("z"), 0), Err(InvalidParam));
    assert_eq!(i.create_blackboard(false, n("z"), 257), Err(InvalidParam));
    assert_eq!(i.create_blackboard(true, n("z"), 8), Err(InvalidMode));
    for k in 1..MAX_BLACKBOARDS {
        i.create_blackboard(false, n(&std::format!("bb{k}")), 8)
            .unwrap();
    }
    assert_eq!(i.create_blackboard(false, n("z"), 8), Err(InvalidConfig));
    assert_eq!(i.get_blackboard_id(&n("bb")), Ok(id));
    assert_eq!(i.get_blackboard_id(&n("zz")), Err(InvalidConfig));
    let mut out = [0u8; 8];
    assert_eq!(
        done(i.read_blackboard(p(0, 1), id, 0, &mut out)),
        Err(NotAvailable)
    );
    assert_eq!(
        done(i.read_blackboard(p(ERROR_HANDLER_SLOT, MCP), id, FINITE, &mut out)),
        Err(InvalidMode)
    );
    assert_eq!(
        done(i.read_blackboard(p(0, 1), -1, 0, &mut out)),
        Err(InvalidParam)
    );
    assert_eq!(
        done(i.read_blackboard(p(0, 1), id, 0, &mut out[..7])),
        Err(InvalidParam)
    );
    assert_eq!(i.display_blackboard(id, b""), Err(InvalidParam));
    assert_eq!(i.display_blackboard(id, b"123456789"), Err(InvalidParam));
    assert_eq!(i.display_blackboard(id + 100, b"1"), Err(InvalidParam));
    assert_eq!(i.display_blackboard(id, b"hello"), Ok(()));
    let status = i.get_blackboard_status(id).unwrap();
    assert_eq!(status.empty_indicator, EmptyIndicator::Occupied);
    assert_eq!(status.max_message_size, 8);
    // Reading does not consume.
    for _ in 0..2 {
        assert_eq!(done(i.read_blackboard(p(0, 1), id, 0, &mut out)), Ok(5));
        assert_eq!(&out[..5], b"hello");
    }
    assert_eq!(i.clear_blackboard(id), Ok(()));
    assert_eq!(i.clear_blackboard(id + 100), Err(InvalidParam));
    assert_eq!(
        i.get_blackboard_status(id).unwrap().empty_indicator,
        EmptyIndicator::Empty
    );
    assert_eq!(i.get_blackboard_status(0), Err(InvalidParam));
    assert_eq!(
        done(i.read_blackboard(p(0, 1), id, 0, &mut out)),
        Err(NotAvailable)
    );
}

#[test]
fn display_wakes_every_reader() {
    let mut i = intra();
    let id = i.create_blackboard(false, n("bb"), 8).unwrap();
    let mut out = [0u8; 8];
    waits(i.read_blackboard(p(0, 1), id, INFINITE, &mut out));
    waits(i.read_blackboard(p(1, 9), id, FINITE, &mut out));
    waits(i.read_blackboard(p(2, 5), id, FINITE, &mut out));
    assert_eq!(i.end_wait(2, true), Some(Err(TimedOut)));
    assert_eq!(i.get_blackboard_status(id).unwrap().waiting_processes, 2);
    assert_eq!(i.display_blackboard(id, b"go"), Ok(()));
    assert_eq!(woken(&mut i), 0b11);
    for slot in [0, 1] {
        assert_eq!(i.end_wait(slot, false), Some(Ok(2)));
        assert_eq!(i.mail(slot), b"go");
    }
    assert_eq!(i.get_blackboard_status(id).unwrap().waiting_processes, 0);
}

// ---------------------------------------------------------------- semaphores

#[test]
fn semaphore_codes() {
    let mut i = intra();
    let id = i.create_semaphore(false, n("s"), 1, 2, Fifo).unwrap();
    assert_eq!(i.create_semaphore(false, n("s"), 0, 1, Fifo), Err(NoAction));
    assert_eq!(
        i.create_semaphore(false, n("z"), 3, 2, Fifo),
        Err(InvalidParam)
    );
    assert_eq!(
        i.create_semaphore(false, n("z"), -1, 2, Fifo),
        Err(InvalidParam)
    );
    assert_eq!(
        i.create_semaphore(false, n("z"), 0, MAX_SEMAPHORE_VALUE + 1, Fifo),
        Err(InvalidParam)
    );
    assert_eq!(
        i.create_semaphore(true, n("z"), 0, 1, Fifo),
        Err(InvalidMode)
    );
    for k in 1..MAX_SEMAPHORES {
        i.create_semaphore(false, n(&std::format!("s{k}")), 0, 1, Fifo)
            .unwrap();
    }
    assert_eq!(
        i.create_semaphore(false, n("z"), 0, 1, Fifo),
        Err(InvalidConfig)
    );
    assert_eq!(i.get_semaphore_id(&n("s")), Ok(id));
    assert_eq!(i.get_semaphore_id(&n("zz")), Err(InvalidConfig));
    assert_eq!(
        done(i.wait_semaphore(p(0, 1), id + 99, 0)),
        Err(InvalidParam)
    );
    assert_eq!(done(i.wait_semaphore(p(0, 1), id, 0)), Ok(()));
    assert_eq!(done(i.wait_semaphore(p(0, 1), id, 0)), Err(NotAvailable));
    assert_eq!(done(i.wait_semaphore(INIT, id, FINITE)), Err(InvalidMode));
    assert_eq!(
        done(i.wait_semaphore(p(ERROR_HANDLER_SLOT, MCP), id, INFINITE)),
        Err(InvalidMode)
    );
    assert_eq!(i.signal_semaphore(id), Ok(()));
    assert_eq!(i.signal_semaphore(id), Ok(()));
    assert_eq!(i.signal_semaphore(id), Err(NoAction));
    assert_eq!(i.signal_semaphore(id + 99), Err(InvalidParam));
    let s = i.get_semaphore_status(id).unwrap();
    assert_eq!(
        (s.current_value, s.maximum_value, s.waiting_processes),
        (2, 2, 0)
    );
    assert_eq!(i.get_semaphore_status(id + 99), Err(InvalidParam));
}

#[test]
fn semaphore_wake_order() {
    for discipline in [Fifo, Prio] {
        let mut i = intra();
        let id = i.create_semaphore(false, n("s"), 0, 5, discipline).unwrap();
        // Priorities 3, 7, 7, 1 in arrival order.
        for (slot, priority) in [(0, 3), (1, 7), (2, 7), (3, 1)] {
            waits(i.wait_semaphore(p(slot, priority), id, INFINITE));
        }
        assert_eq!(i.get_semaphore_status(id).unwrap().waiting_processes, 4);
        let expected = if discipline == Fifo {
            [0, 1, 2, 3]
        } else {
            [1, 2, 0, 3]
        };
        for slot in expected {
            assert_eq!(i.signal_semaphore(id), Ok(()));
            assert_eq!(woken(&mut i), 1 << slot);
            assert_eq!(i.end_wait(slot, false), Some(Ok(0)));
        }
        // The value never went up: each unit went to a waiter.
        assert_eq!(i.get_semaphore_status(id).unwrap().current_value, 0);
    }
}

#[test]
fn semaphore_time_out_leaves_the_queue() {
    let mut i = intra();
    let id = i.create_semaphore(false, n("s"), 0, 1, Fifo).unwrap();
    waits(i.wait_semaphore(p(0, 1), id, FINITE));
    waits(i.wait_semaphore(p(1, 1), id, FINITE));
    // Woken early without an outcome: it waits on.
    assert_eq!(i.end_wait(0, false), None);
    assert_eq!(i.end_wait(0, true), Some(Err(TimedOut)));
    assert_eq!(i.signal_semaphore(id), Ok(()));
    assert_eq!(woken(&mut i), 1 << 1);
    assert_eq!(
        i.end_wait(1, true),
        Some(Ok(0)),
        "decided before the time-out"
    );
    assert_eq!(i.signal_semaphore(id), Ok(()));
    assert_eq!(i.get_semaphore_status(id).unwrap().current_value, 1);
}

#[test]
fn stopped_waiter_leaves_the_queue() {
    let mut i = intra();
    let id = i.create_semaphore(false, n("s"), 0, 1, Fifo).unwrap();
    waits(i.wait_semaphore(p(0, 1), id, INFINITE));
    waits(i.wait_semaphore(p(1, 1), id, INFINITE));
    i.forget(0);
    assert_eq!(i.signal_semaphore(id), Ok(()));
    assert_eq!(woken(&mut i), 1 << 1);
}

// ---------------------------------------------------------------- events

#[test]
fn event_codes_and_wakes() {
    let mut i = intra();
    let id = i.create_event(false, n("e")).unwrap();
    assert_eq!(i.create_event(false, n("e")), Err(NoAction));
    assert_eq!(i.create_event(true, n("z")), Err(InvalidMode));
    for k in 1..MAX_EVENTS {
        i.create_event(false, n(&std::format!("e{k}"))).unwrap();
    }
    assert_eq!(i.create_event(false, n("z")), Err(InvalidConfig));
    assert_eq!(i.get_event_id(&n("e")), Ok(id));
    assert_eq!(i.get_event_id(&n("zz")), Err(InvalidConfig));
    assert_eq!(done(i.wait_event(p(0, 1), id, 0)), Err(NotAvailable));
    assert_eq!(done(i.wait_event(p(0, 1), id + 99, 0)), Err(InvalidParam));
    assert_eq!(done(i.wait_event(INIT, id, FINITE)), Err(InvalidMode));
    assert_eq!(
        done(i.wait_event(p(ERROR_HANDLER_SLOT, MCP), id, INFINITE)),
        Err(InvalidMode)
    );
    waits(i.wait_event(p(0, 1), id, INFINITE));
    waits(i.wait_event(p(1, 50), id, FINITE));
    waits(i.wait_event(p(2, 3), id, FINITE));
    assert_eq!(i.end_wait(2, true), Some(Err(TimedOut)));
    let s = i.get_event_status(id).unwrap();
    assert_eq!((s.event_state, s.waiting_processes), (EventState::Down, 2));
    assert_eq!(i.set_event(id + 99), Err(InvalidParam));
    assert_eq!(i.set_event(id), Ok(()));
    assert_eq!(woken(&mut i), 0b11);
    assert_eq!(i.end_wait(0, false), Some(Ok(0)));
    assert_eq!(i.end_wait(1, false), Some(Ok(0)));
    assert_eq!(done(i.wait_event(p(3, 1), id, 0)), Ok(()));
    assert_eq!(done(i.wait_event(p(3, 1), id, INFINITE)), Ok(()));
    assert_eq!(i.get_event_status(id).unwrap().event_state, EventState::Up);
    assert_eq!(i.reset_event(id + 99), Err(InvalidParam));
    assert_eq!(i.reset_event(id), Ok(()));
    assert_eq!(done(i.wait_event(p(3, 1), id, 0)), Err(NotAvailable));
    assert_eq!(i.get_event_status(id + 99), Err(InvalidParam));
}

// ---------------------------------------------------------------- mutexes

#[test]
fn create_mutex_codes() {
    let mut i = intra();
    let id = i.create_mutex(false, MCP, n("m"), 50, Fifo).unwrap();
    assert_eq!(i.create_mutex(false, MCP, n("m"), 50, Fifo), Err(NoAction));
    assert_eq!(
        i.create_mutex(false, MCP, n("z"), 0, Fifo),
        Err(InvalidParam)
    );
    assert_eq!(
        i.create_mutex(false, MCP, n("z"), 240, Fifo),
        Err(InvalidParam)
    );
    assert_eq!(
        i.create_mutex(false, MCP, n("z"), i32::from(MCP), Fifo),
        Err(InvalidConfig)
    );
    assert_eq!(
        i.create_mutex(true, MCP, n("z"), 50, Fifo),
        Err(InvalidMode)
    );
    for k in 1..MAX_MUTEXES {
        i.create_mutex(false, MCP, n(&std::format!("m{k}")), 50, Fifo)
            .unwrap();
    }
    assert_eq!(
        i.create_mutex(false, MCP, n("z"), 50, Fifo),
        Err(InvalidConfig)
    );
    assert_eq!(i.get_mutex_id(&n("m")), Ok(id));
    assert_eq!(i.get_mutex_id(&n("zz")), Err(InvalidConfig));
    assert_eq!(i.get_mutex_status(id + 99), Err(InvalidParam));
    assert_eq!(i.get_mutex_status(PREEMPTION_LOCK_MUTEX), Err(InvalidParam));
}

#[test]
fn mutex_ceiling_lock_count_and_codes() {
    let mut i = intra();
    let id = i.create_mutex(false, MCP, n("m"), 50, Fifo).unwrap();
    let other = i.create_mutex(false, MCP, n("o"), 60, Fifo).unwrap();
    assert_eq!(
        done(i.acquire_mutex(p(0, 10), id + 99, 0)),
        Err(InvalidParam)
    );
    assert_eq!(
        done(i.acquire_mutex(p(0, 10), PREEMPTION_LOCK_MUTEX, 0)),
        Err(InvalidParam)
    );
    assert_eq!(done(i.acquire_mutex(INIT, id, 0)), Err(InvalidMode));
    assert_eq!(
        done(i.acquire_mutex(p(ERROR_HANDLER_SLOT, MCP), id, 0)),
        Err(InvalidMode)
    );
    // Above the ceiling.
    assert_eq!(done(i.acquire_mutex(p(0, 51), id, 0)), Err(InvalidConfig));
    assert_eq!(done(i.acquire_mutex(p(0, 10), id, 0)), Ok(()));
    assert_eq!(i.take_priority(0), Some(50), "raised to the ceiling");
    assert_eq!(i.process_mutex_state(0), id);
    assert_eq!(i.process_mutex_state(1), NO_MUTEX_OWNED);
    // Recursive: the lock count goes up to MAX_LOCK_LEVEL.
    for _ in 1..MAX_LOCK_LEVEL {
        assert_eq!(done(i.acquire_mutex(p(0, 50), id, INFINITE)), Ok(()));
    }
    assert_eq!(done(i.acquire_mutex(p(0, 50), id, 0)), Err(InvalidConfig));
    let s = i.get_mutex_status(id).unwrap();
    assert_eq!(
        (s.mutex_owner, s.mutex_state, s.mutex_priority, s.lock_count),
        (id_of(0), MutexState::Owned, 50, MAX_LOCK_LEVEL)
    );
    // One mutex at a time, and no other waits while owning one.
    assert_eq!(done(i.acquire_mutex(p(0, 50), other, 0)), Err(InvalidMode));
    let sem = i.create_semaphore(false, n("s"), 0, 1, Fifo).unwrap();
    assert_eq!(
        done(i.wait_semaphore(p(0, 50), sem, FINITE)),
        Err(InvalidMode)
    );
    assert_eq!(done(i.wait_semaphore(p(0, 50), sem, 0)), Err(NotAvailable));
    // Others: not the owner.
    assert_eq!(done(i.acquire_mutex(p(1, 10), id, 0)), Err(NotAvailable));
    assert_eq!(i.release_mutex(p(1, 10), id), Err(InvalidMode));
    assert_eq!(i.release_mutex(INIT, id), Err(InvalidMode));
    assert_eq!(i.release_mutex(p(1, 10), id + 99), Err(InvalidParam));
    for _ in 1..MAX_LOCK_LEVEL {
        assert_eq!(i.release_mutex(p(0, 50), id), Ok(()));
    }
    assert_eq!(i.take_priority(0), None, "still owned");
    assert_eq!(i.release_mutex(p(0, 50), id), Ok(()));
    assert_eq!(i.take_priority(0), Some(10), "the retained priority");
    assert_eq!(i.release_mutex(p(0, 10), id), Err(InvalidMode));
    let s = i.get_mutex_status(id).unwrap();
    assert_eq!(
        (s.mutex_owner, s.mutex_state, s.lock_count),
        (NULL_PROCESS_ID, MutexState::Available, 0)
    );
}

#[test]
fn mutex_hand_over_order() {
    for discipline in [Fifo, Prio] {
        let mut i = intra();
        let id = i.create_mutex(false, MCP, n("m"), 60, discipline).unwrap();
        assert_eq!(done(i.acquire_mutex(p(0, 10), id, 0)), Ok(()));
        i.take_priority(0);
        for (slot, priority) in [(1, 20), (2, 40), (3, 40)] {
            waits(i.acquire_mutex(p(slot, priority), id, INFINITE));
        }
        waits(i.acquire_mutex(p(4, 55), id, FINITE));
        assert_eq!(i.end_wait(4, true), Some(Err(TimedOut)));
        assert_eq!(i.get_mutex_status(id).unwrap().waiting_processes, 3);
        let order = if discipline == Fifo {
            [(1, 20), (2, 40), (3, 40)]
        } else {
            [(2, 40), (3, 40), (1, 20)]
        };
        let mut owner = (0, 10);
        for (slot, priority) in order {
            assert_eq!(i.release_mutex(p(owner.0, 60), id), Ok(()));
            assert_eq!(i.take_priority(owner.0), Some(owner.1));
            assert_eq!(woken(&mut i), 1 << slot);
            assert_eq!(i.end_wait(slot, false), Some(Ok(0)));
            assert_eq!(i.take_priority(slot), Some(60));
            assert_eq!(i.get_mutex_status(id).unwrap().mutex_owner, id_of(slot));
            owner = (slot, priority);
        }
    }
}

#[test]
fn reset_mutex_and_stop_of_the_owner() {
    let mut i = intra();
    let id = i.create_mutex(false, MCP, n("m"), 60, Fifo).unwrap();
    assert_eq!(done(i.acquire_mutex(p(0, 10), id, 0)), Ok(()));
    assert_eq!(done(i.acquire_mutex(p(0, 60), id, 0)), Ok(()));
    i.take_priority(0);
    waits(i.acquire_mutex(p(1, 20), id, INFINITE));
    waits(i.acquire_mutex(p(2, 20), id, INFINITE));
    assert_eq!(i.reset_mutex(id + 99, 0), Err(InvalidParam));
    assert_eq!(i.reset_mutex(id, 3), Err(InvalidMode));
    // Whatever the lock count.
    assert_eq!(i.reset_mutex(id, 0), Ok(()));
    assert_eq!(i.take_priority(0), Some(10));
    assert_eq!(woken(&mut i), 1 << 1);
    assert_eq!(i.end_wait(1, false), Some(Ok(0)));
    // A stopped owner hands the mutex on.
    i.forget(1);
    assert_eq!(woken(&mut i), 1 << 2);
    assert_eq!(i.process_mutex_state(2), id);
    // SET_PRIORITY of an owner changes what it gets back.
    assert!(i.set_retained_priority(2, 33));
    assert!(!i.set_retained_priority(1, 33));
    i.take_priority(2);
    assert_eq!(i.release_mutex(p(2, 60), id), Ok(()));
    assert_eq!(i.take_priority(2), Some(33));
}

#[test]
fn reset_clears_everything() {
    let mut i = intra();
    let id = i.create_semaphore(false, n("s"), 0, 1, Fifo).unwrap();
    waits(i.wait_semaphore(p(0, 1), id, INFINITE));
    i.create_buffer(false, n("b"), 256, 100, Fifo).unwrap();
    i.reset();
    assert_eq!(i.get_semaphore_id(&n("s")), Err(InvalidConfig));
    assert_eq!(i.get_semaphore_status(id), Err(InvalidParam));
    assert!(!i.is_waiting(0));
    i.create_buffer(false, n("b"), 256, 100, Fifo).unwrap();
}

#[test]
fn a_mutex_owner_may_only_poll_other_objects() {
    let mut i = intra();
    let m = i.create_mutex(false, MCP, n("m"), 50, Fifo).unwrap();
    let buffer = i.create_buffer(false, n("b"), 4, 1, Fifo).unwrap();
    let board = i.create_blackboard(false, n("bb"), 4).unwrap();
    let event = i.create_event(false, n("e")).unwrap();
    assert_eq!(done(i.acquire_mutex(p(0, 10), m, 0)), Ok(()));
    let owner = p(0, 50);
    let mut out = [0u8; 4];
    for time_out in [FINITE, INFINITE] {
        assert_eq!(
            done(i.receive_buffer(owner, buffer, time_out, &mut out)),
            Err(InvalidMode)
        );
        assert_eq!(
            done(i.read_blackboard(owner, board, time_out, &mut out)),
            Err(InvalidMode)
        );
        assert_eq!(done(i.wait_event(owner, event, time_out)), Err(InvalidMode));
    }
    assert_eq!(
        done(i.receive_buffer(owner, buffer, 0, &mut out)),
        Err(NotAvailable)
    );
    assert_eq!(done(i.send_buffer(owner, buffer, b"1", 0)), Ok(()));
    assert_eq!(
        done(i.send_buffer(owner, buffer, b"2", FINITE)),
        Err(InvalidMode)
    );
    // Nothing was queued.
    assert!(!i.is_waiting(0));
    // The owner may not wait at all (the runtime refuses its TIMED_WAIT, PERIODIC_WAIT,
    // SUSPEND_SELF, and a SUSPEND of it), until it releases the mutex.
    assert!(i.owns_a_mutex(0) && !i.owns_a_mutex(1));
    assert_eq!(i.release_mutex(owner, m), Ok(()));
    assert!(!i.owns_a_mutex(0));
    i.lock_preemption(p(1, 10), true, MCP).expect("locked");
    assert!(i.owns_a_mutex(1));
}

// ---------------------------------------------------------------- preemption lock

#[test]
fn preemption_lock_levels_and_codes() {
    let mut i = intra();
    let lock_priority = Intra::lock_priority(MCP);
    // Not in NORMAL mode, the error handler, the initialisation thread: NO_ACTION.
    assert_eq!(i.lock_preemption(p(0, 10), false, MCP), Err(NoAction));
    assert_eq!(
        i.lock_preemption(p(ERROR_HANDLER_SLOT, MCP), true, MCP),
        Err(NoAction)
    );
    assert_eq!(i.lock_preemption(INIT, true, MCP), Err(NoAction));
    assert_eq!(i.unlock_preemption(p(0, 10), true), Err(NoAction));
    assert_eq!(i.lock_level(), 0);

    // Levels 1..=MAX_LOCK_LEVEL, then INVALID_CONFIG; the owner runs above every process.
    assert_eq!(i.lock_preemption(p(0, 10), true, MCP), Ok(1));
    assert_eq!(i.take_priority(0), Some(lock_priority));
    assert_eq!(lock_priority, MCP);
    for level in 2..=MAX_LOCK_LEVEL {
        assert_eq!(i.lock_preemption(p(0, lock_priority), true, MCP), Ok(level));
    }
    assert_eq!(
        i.lock_preemption(p(0, lock_priority), true, MCP),
        Err(InvalidConfig)
    );
    assert_eq!(i.lock_level(), MAX_LOCK_LEVEL);
    assert_eq!(i.process_mutex_state(0), PREEMPTION_LOCK_MUTEX);
    // Not the owner: NO_ACTION for unlock, INVALID_MODE for a second lock.
    assert_eq!(i.unlock_preemption(p(1, 10), true), Err(NoAction));
    assert_eq!(i.lock_preemption(p(1, 10), true, MCP), Err(InvalidMode));
    // Unlocking outside NORMAL mode (after a mode change) or from the handler: NO_ACTION.
    assert_eq!(
        i.unlock_preemption(p(0, lock_priority), false),
        Err(NoAction)
    );
    for level in (1..MAX_LOCK_LEVEL).rev() {
        assert_eq!(i.unlock_preemption(p(0, lock_priority), true), Ok(level));
        assert_eq!(i.take_priority(0), None, "still locked at {level}");
    }
    assert_eq!(i.unlock_preemption(p(0, lock_priority), true), Ok(0));
    assert_eq!(i.take_priority(0), Some(10));
    assert_eq!(i.lock_level(), 0);
    assert_eq!(i.process_mutex_state(0), NO_MUTEX_OWNED);
    assert_eq!(i.unlock_preemption(p(0, 10), true), Err(NoAction));
}

#[test]
fn the_preemption_lock_owner_may_not_wait_or_take_a_mutex() {
    let mut i = intra();
    let s = i
        .create_semaphore(false, n("s"), 0, 1, Fifo)
        .expect("semaphore");
    let e = i.create_event(false, n("e")).expect("event");
    let b = i.create_buffer(false, n("b"), 8, 1, Fifo).expect("buffer");
    let m = i.create_mutex(false, MCP, n("m"), 50, Fifo).expect("mutex");
    let owner = p(0, Intra::lock_priority(MCP));
    i.lock_preemption(p(0, 10), true, MCP).expect("locked");
    assert_eq!(done(i.wait_semaphore(owner, s, FINITE)), Err(InvalidMode));
    assert_eq!(done(i.wait_event(owner, e, INFINITE)), Err(InvalidMode));
    let mut out = [0u8; 8];
    assert_eq!(
        done(i.receive_buffer(owner, b, FINITE, &mut out)),
        Err(InvalidMode)
    );
    // Polling is still allowed.
    assert_eq!(done(i.wait_semaphore(owner, s, 0)), Err(NotAvailable));
    assert_eq!(done(i.acquire_mutex(owner, m, 0)), Err(InvalidMode));
    // SET_PRIORITY of the owner changes only what it gets back.
    assert!(i.set_retained_priority(0, 20));
    assert_eq!(i.unlock_preemption(owner, true), Ok(0));
    assert_eq!(i.take_priority(0), Some(20));
    // A mutex owner cannot lock preemption; STOP of the owner clears the lock.
    assert_eq!(done(i.acquire_mutex(p(1, 20), m, 0)), Ok(()));
    assert_eq!(i.lock_preemption(p(1, 50), true, MCP), Err(InvalidMode));
    i.lock_preemption(p(2, 10), true, MCP).expect("locked");
    i.forget(2);
    assert_eq!(i.lock_level(), 0);
    assert_eq!(i.lock_preemption(p(3, 10), true, MCP), Ok(1));
    i.reset();
    assert_eq!(i.lock_level(), 0);
}
