use super::*;
use crate::testsys::{blob, with};
use config::decode;
use proptest::prelude::*;
use std::collections::VecDeque;
use std::vec;
use std::vec::Vec;

const MS: u64 = 1_000_000;

/// Sampling `a.out` (8 bytes) -> `b.in` (16 bytes, refresh 20 ms) and `b.raw` (8 bytes, no
/// refresh); queuing `a.tx` (16 bytes, depth 2) -> `b.rx` (32 bytes, depth 3).
fn system_text() -> std::string::String {
    with(&[
        (
            "# a",
            r#"ports.out = { kind = "sampling", direction = "out", size = 8 }
ports.tx = { kind = "queuing", direction = "out", size = 16, depth = 2 }"#,
        ),
        (
            "# b",
            r#"ports.in = { kind = "sampling", direction = "in", size = 16, refresh = "20ms" }
ports.raw = { kind = "sampling", direction = "in", size = 8 }
ports.rx = { kind = "queuing", direction = "in", size = 32, depth = 3 }"#,
        ),
        (
            "# tail",
            r#"[[channels]]
kind = "sampling"
from = "a.out"
to = ["b.in", "b.raw"]

[[channels]]
kind = "queuing"
from = "a.tx"
to = "b.rx""#,
        ),
    ])
}

/// Global index of `partition.port`, with the partition's index.
fn port(system: &SystemView<'_>, partition: &str, name: &str) -> (usize, usize) {
    let p = system.find_partition(partition).expect("partition");
    (p.index, p.find_port(name).expect("port").index)
}

type Done = Vec<(u64, usize, ReturnCode, Vec<u8>)>;

fn collect(done: &mut Done) -> impl FnMut(Completion<'_>) + '_ {
    |c| done.push((c.token, c.port, c.code, c.message.to_vec()))
}

fn no_completion(c: Completion<'_>) {
    panic!("unexpected completion {c:?}");
}

fn sent() -> Outcome {
    Outcome::Done {
        code: ReturnCode::NoError,
        len: 0,
    }
}

fn failed(code: ReturnCode) -> Outcome {
    Outcome::Done { code, len: 0 }
}

/// The ports of the test system; `f` gets them with the indices (a, out, tx, b, in, raw, rx).
fn with_ports(f: impl FnOnce(&mut Ports<'_>, [usize; 7])) {
    let bytes = blob(&system_text());
    let system = decode(&bytes).unwrap();
    let (a, out) = port(&system, "a", "out");
    let (_, tx) = port(&system, "a", "tx");
    let (b, inp) = port(&system, "b", "in");
    let (_, raw) = port(&system, "b", "raw");
    let (_, rx) = port(&system, "b", "rx");
    let mut arena = vec![0xa5u8; arena_size(&system)];
    let mut ports = Ports::new(&system, &mut arena).unwrap();
    f(&mut ports, [a, out, tx, b, inp, raw, rx]);
    ports.check_invariants();
}

#[test]
fn arena_size_is_exact() {
    let bytes = blob(&system_text());
    let system = decode(&bytes).unwrap();
    // sampling: 8; queuing: (2 + 3) slots of 4 + 16, plus 8 waiter records of 24 + 16.
    let expected = 8 + 5 * 20 + MAX_WAITERS * 40;
    assert_eq!(arena_size(&system), expected);
    let mut short = vec![0u8; expected - 1];
    assert_eq!(
        Ports::new(&system, &mut short).err(),
        Some(PortsError::ArenaTooSmall {
            needed: expected,
            given: expected - 1
        })
    );
    let mut exact = vec![0u8; expected];
    assert!(Ports::new(&system, &mut exact).is_ok());
    // A system without channels needs nothing.
    let empty = blob(crate::testsys::TWO);
    let empty = decode(&empty).unwrap();
    assert_eq!(arena_size(&empty), 0);
    let mut none: [u8; 0] = [];
    let ports = Ports::new(&empty, &mut none).unwrap();
    assert_eq!(ports.port_count(), 0);
}

#[test]
fn sampling_read_before_write_is_no_action() {
    with_ports(|ports, [_, _, _, b, inp, raw, _]| {
        let mut buf = [0u8; 16];
        for port in [inp, raw] {
            assert_eq!(
                ports.read_sampling(b, port, 5, &mut buf),
                Sample {
                    code: ReturnCode::NoAction,
                    len: 0,
                    validity: Validity::Invalid
                }
            );
        }
    });
}

#[test]
fn sampling_latest_message_and_validity() {
    with_ports(|ports, [a, out, _, b, inp, raw, _]| {
        let mut buf = [0u8; 16];
        assert_eq!(
            ports.write_sampling(a, out, b"abcdefgh", MS),
            ReturnCode::NoError
        );
        assert_eq!(
            ports.write_sampling(a, out, b"xy", 2 * MS),
            ReturnCode::NoError
        );
        let s = ports.read_sampling(b, inp, 2 * MS, &mut buf);
        assert_eq!(
            (s.code, s.len, s.validity),
            (ReturnCode::NoError, 2, Validity::Valid)
        );
        assert_eq!(&buf[..2], b"xy");
        // Age exactly the refresh period: still valid; one ns more: invalid but returned.
        let s = ports.read_sampling(b, inp, 22 * MS, &mut buf);
        assert_eq!((s.code, s.validity), (ReturnCode::NoError, Validity::Valid));
        buf = [0; 16];
        let s = ports.read_sampling(b, inp, 22 * MS + 1, &mut buf);
        assert_eq!(
            (s.code, s.len, s.validity),
            (ReturnCode::NoError, 2, Validity::Invalid)
        );
        assert_eq!(&buf[..2], b"xy");
        // A destination without a refresh period sees every message as valid.
        let mut small = [0u8; 8];
        let s = ports.read_sampling(b, raw, u64::MAX, &mut small);
        assert_eq!(
            (s.code, s.len, s.validity),
            (ReturnCode::NoError, 2, Validity::Valid)
        );
        // Reading does not consume.
        let s = ports.read_sampling(b, raw, 3 * MS, &mut small);
        assert_eq!((s.code, s.len), (ReturnCode::NoError, 2));
        // A clock behind the write time counts as age 0.
        let s = ports.read_sampling(b, inp, 0, &mut buf);
        assert_eq!(s.validity, Validity::Valid);
    });
}

#[test]
fn sampling_errors() {
    with_ports(|ports, [a, out, tx, b, inp, _, _]| {
        let mut buf = [0u8; 16];
        // Longer than the port: INVALID_CONFIG (ARINC); empty: INVALID_PARAM.
        assert_eq!(
            ports.write_sampling(a, out, &[1; 9], 0),
            ReturnCode::InvalidConfig
        );
        assert_eq!(
            ports.write_sampling(a, out, &[], 0),
            ReturnCode::InvalidParam
        );
        // Wrong direction.
        assert_eq!(
            ports.write_sampling(b, inp, b"x", 0),
            ReturnCode::InvalidMode
        );
        assert_eq!(
            ports.read_sampling(a, out, 0, &mut buf).code,
            ReturnCode::InvalidMode
        );
        // Another partition's port, an unknown index, a queuing port.
        assert_eq!(
            ports.write_sampling(b, out, b"x", 0),
            ReturnCode::InvalidParam
        );
        assert_eq!(
            ports.read_sampling(a, inp, 0, &mut buf).code,
            ReturnCode::InvalidParam
        );
        assert_eq!(
            ports.write_sampling(a, 99, b"x", 0),
            ReturnCode::InvalidParam
        );
        assert_eq!(
            ports.write_sampling(a, usize::MAX, b"x", 0),
            ReturnCode::InvalidParam
        );
        assert_eq!(
            ports.write_sampling(a, tx, b"x", 0),
            ReturnCode::InvalidParam
        );
        // A buffer shorter than the port (glue contract).
        assert_eq!(ports.write_sampling(a, out, b"x", 0), ReturnCode::NoError);
        let mut short = [0u8; 15];
        assert_eq!(
            ports.read_sampling(b, inp, 0, &mut short).code,
            ReturnCode::InvalidParam
        );
        // A refused write changes nothing.
        assert_eq!(
            ports.write_sampling(a, out, &[7; 9], 5),
            ReturnCode::InvalidConfig
        );
        let s = ports.read_sampling(b, inp, 0, &mut buf);
        assert_eq!((s.len, buf[0]), (1, b'x'));
    });
}

#[test]
fn sampling_status() {
    with_ports(|ports, [a, out, tx, b, inp, raw, _]| {
        let mut buf = [0u8; 16];
        assert_eq!(
            ports.sampling_status(b, inp),
            Ok(SamplingStatus {
                max_message_size: 16,
                direction: Direction::In,
                refresh_period: 20 * MS,
                last_msg_validity: Validity::Invalid
            })
        );
        assert_eq!(
            ports.sampling_status(a, out),
            Ok(SamplingStatus {
                max_message_size: 8,
                direction: Direction::Out,
                refresh_period: 0,
                last_msg_validity: Validity::Invalid
            })
        );
        ports.write_sampling(a, out, b"m", 0);
        ports.read_sampling(b, inp, 1, &mut buf);
        assert_eq!(
            ports.sampling_status(b, inp).unwrap().last_msg_validity,
            Validity::Valid
        );
        ports.read_sampling(b, inp, 30 * MS, &mut buf);
        assert_eq!(
            ports.sampling_status(b, inp).unwrap().last_msg_validity,
            Validity::Invalid
        );
        assert_eq!(
            ports.sampling_status(b, raw).unwrap().last_msg_validity,
            Validity::Invalid
        );
        assert_eq!(ports.sampling_status(a, inp), Err(ReturnCode::InvalidParam));
        assert_eq!(ports.sampling_status(a, tx), Err(ReturnCode::InvalidParam));
        assert_eq!(ports.queuing_status(a, out), Err(ReturnCode::InvalidParam));
    });
}

#[test]
fn sampling_reset() {
    with_ports(|ports, [a, out, _, b, inp, _, _]| {
        let mut buf = [0u8; 16];
        ports.write_sampling(a, out, b"old", 0);
        // The source restarts: the message already sent stays.
        ports.reset_partition(a, no_completion);
        assert_eq!(ports.read_sampling(b, inp, 1, &mut buf).len, 3);
        // The destination restarts: empty until the next write.
        ports.reset_partition(b, no_completion);
        assert_eq!(
            ports.read_sampling(b, inp, 1, &mut buf).code,
            ReturnCode::NoAction
        );
        assert_eq!(
            ports.sampling_status(b, inp).unwrap().last_msg_validity,
            Validity::Invalid
        );
        ports.write_sampling(a, out, b"new!", 2);
        let s = ports.read_sampling(b, inp, 3, &mut buf);
        assert_eq!((s.code, s.len), (ReturnCode::NoError, 4));
        assert_eq!(&buf[..4], b"new!");
    });
}

#[test]
fn queuing_fifo_capacity_and_sizes() {
    with_ports(|ports, [a, _, tx, b, _, _, rx]| {
        let mut buf = [0u8; 32];
        // Capacity = source depth 2 + destination depth 3.
        for i in 0..5u8 {
            let msg = vec![i; 1 + i as usize];
            assert_eq!(
                ports.send_queuing(a, tx, &msg, 0, 0, 100, no_completion),
                sent()
            );
        }
        let st = ports.queuing_status(a, tx).unwrap();
        assert_eq!(
            (st.nb_message, st.max_nb_message, st.max_message_size),
            (2, 2, 16)
        );
        let st = ports.queuing_status(b, rx).unwrap();
        assert_eq!(
            (st.nb_message, st.max_nb_message, st.max_message_size),
            (3, 3, 32)
        );
        assert_eq!(
            ports.send_queuing(a, tx, b"x", 0, 0, 100, no_completion),
            failed(ReturnCode::NotAvailable)
        );
        for i in 0..5u8 {
            let out = ports.receive_queuing(b, rx, 0, 0, 200, &mut buf, no_completion);
            assert_eq!(
                out,
                Outcome::Done {
                    code: ReturnCode::NoError,
                    len: 1 + i as usize
                }
            );
            assert!(buf[..1 + i as usize].iter().all(|&x| x == i));
        }
        assert_eq!(
            ports.receive_queuing(b, rx, 0, 0, 200, &mut buf, no_completion),
            failed(ReturnCode::NotAvailable)
        );
        // Sizes: the largest message is the source's 16 bytes.
        assert_eq!(
            ports.send_queuing(a, tx, &[1; 17], 0, 0, 1, no_completion),
            failed(ReturnCode::InvalidConfig)
        );
        assert_eq!(
            ports.send_queuing(a, tx, &[1; 16], 0, 0, 1, no_completion),
            sent()
        );
        assert_eq!(
            ports.send_queuing(a, tx, &[], 0, 0, 1, no_completion),
            failed(ReturnCode::InvalidParam)
        );
    });
}

#[test]
fn queuing_errors() {
    with_ports(|ports, [a, out, tx, b, _, _, rx]| {
        let mut buf = [0u8; 32];
        let wait = 5 * MS;
        assert_eq!(
            ports.send_queuing(b, rx, b"x", 0, wait, 1, no_completion),
            failed(ReturnCode::InvalidMode)
        );
        assert_eq!(
            ports.receive_queuing(a, tx, 0, wait, 1, &mut buf, no_completion),
            failed(ReturnCode::InvalidMode)
        );
        assert_eq!(
            ports.send_queuing(b, tx, b"x", 0, wait, 1, no_completion),
            failed(ReturnCode::InvalidParam)
        );
        assert_eq!(
            ports.receive_queuing(a, rx, 0, wait, 1, &mut buf, no_completion),
            failed(ReturnCode::InvalidParam)
        );
        assert_eq!(
            ports.send_queuing(a, out, b"x", 0, wait, 1, no_completion),
            failed(ReturnCode::InvalidParam)
        );
        assert_eq!(
            ports.send_queuing(a, 1000, b"x", 0, wait, 1, no_completion),
            failed(ReturnCode::InvalidParam)
        );
        let mut short = [0u8; 31];
        assert_eq!(
            ports.receive_queuing(b, rx, 0, wait, 1, &mut short, no_completion),
            failed(ReturnCode::InvalidParam)
        );
        assert_eq!(
            ports.clear_queuing(a, tx, 0, no_completion),
            ReturnCode::InvalidMode
        );
        assert_eq!(
            ports.clear_queuing(a, rx, 0, no_completion),
            ReturnCode::InvalidParam
        );
        // None of this parked anybody.
        assert_eq!(ports.queuing_status(b, rx).unwrap().waiting_processes, 0);
        assert_eq!(ports.next_deadline(), None);
    });
}

#[test]
fn parked_receiver_gets_the_next_message() {
    with_ports(|ports, [a, _, tx, b, _, _, rx]| {
        let mut buf = [0u8; 32];
        assert_eq!(
            ports.receive_queuing(b, rx, 0, TIMEOUT_INFINITE, 7, &mut buf, no_completion),
            Outcome::Parked
        );
        assert_eq!(
            ports.receive_queuing(b, rx, 0, 10 * MS, 8, &mut buf, no_completion),
            Outcome::Parked
        );
        let st = ports.queuing_status(b, rx).unwrap();
        assert_eq!((st.nb_message, st.waiting_processes), (0, 2));
        assert_eq!(ports.queuing_status(a, tx).unwrap().waiting_processes, 0);
        assert_eq!(ports.next_deadline(), Some(10 * MS));
        let mut done = Done::new();
        assert_eq!(
            ports.send_queuing(a, tx, b"hello", MS, 0, 1, collect(&mut done)),
            sent()
        );
        assert_eq!(done, vec![(7, rx, ReturnCode::NoError, b"hello".to_vec())]);
        done.clear();
        assert_eq!(
            ports.send_queuing(a, tx, b"two", MS, 0, 1, collect(&mut done)),
            sent()
        );
        assert_eq!(done, vec![(8, rx, ReturnCode::NoError, b"two".to_vec())]);
        // Handed over, not queued.
        assert_eq!(ports.queuing_status(b, rx).unwrap().nb_message, 0);
        assert_eq!(ports.next_deadline(), None);
    });
}

#[test]
fn parked_senders_enter_in_fifo_order() {
    with_ports(|ports, [a, _, tx, b, _, _, rx]| {
        let mut buf = [0u8; 32];
        for i in 0..5u8 {
            assert_eq!(
                ports.send_queuing(a, tx, &[i], 0, 0, 0, no_completion),
                sent()
            );
        }
        assert_eq!(
            ports.send_queuing(a, tx, &[10, 10], 0, 50, 10, no_completion),
            Outcome::Parked
        );
        assert_eq!(
            ports.send_queuing(a, tx, &[11, 11, 11], 0, TIMEOUT_INFINITE, 11, no_completion),
            Outcome::Parked
        );
        // A new sender does not overtake the parked ones, even with time-out 0.
        assert_eq!(
            ports.send_queuing(a, tx, &[12], 0, 0, 12, no_completion),
            failed(ReturnCode::NotAvailable)
        );
        let st = ports.queuing_status(a, tx).unwrap();
        assert_eq!((st.nb_message, st.waiting_processes), (2, 2));
        assert_eq!(ports.queuing_status(b, rx).unwrap().waiting_processes, 0);
        let mut done = Done::new();
        let out = ports.receive_queuing(b, rx, 1, 0, 99, &mut buf, collect(&mut done));
        assert_eq!(
            out,
            Outcome::Done {
                code: ReturnCode::NoError,
                len: 1
            }
        );
        assert_eq!(buf[0], 0);
        assert_eq!(done, vec![(10, tx, ReturnCode::NoError, vec![])]);
        done.clear();
        ports.receive_queuing(b, rx, 1, 0, 99, &mut buf, collect(&mut done));
        assert_eq!(done, vec![(11, tx, ReturnCode::NoError, vec![])]);
        done.clear();
        // The queue now ends with the two admitted messages.
        let mut got = Vec::new();
        while let Outcome::Done {
            code: ReturnCode::NoError,
            len,
        } = ports.receive_queuing(b, rx, 2, 0, 99, &mut buf, collect(&mut done))
        {
            got.push(buf[..len].to_vec());
        }
        assert_eq!(
            got,
            vec![vec![2], vec![3], vec![4], vec![10, 10], vec![11, 11, 11]]
        );
        assert!(done.is_empty());
    });
}

#[test]
fn time_outs() {
    with_ports(|ports, [a, _, tx, b, _, _, rx]| {
        let mut buf = [0u8; 32];
        ports.receive_queuing(b, rx, 0, 30, 1, &mut buf, no_completion);
        ports.receive_queuing(b, rx, 5, 10, 2, &mut buf, no_completion);
        ports.receive_queuing(b, rx, 5, TIMEOUT_INFINITE, 3, &mut buf, no_completion);
        let mut done = Done::new();
        assert_eq!(ports.expire(14, collect(&mut done)), Some(15));
        assert!(done.is_empty());
        // A deadline equal to now has passed.
        assert_eq!(ports.expire(15, collect(&mut done)), Some(30));
        assert_eq!(done, vec![(2, rx, ReturnCode::TimedOut, vec![])]);
        done.clear();
        assert_eq!(ports.expire(u64::MAX - 1, collect(&mut done)), None);
        assert_eq!(done, vec![(1, rx, ReturnCode::TimedOut, vec![])]);
        done.clear();
        // The infinite waiter is still there.
        assert_eq!(ports.queuing_status(b, rx).unwrap().waiting_processes, 1);
        assert!(ports.cancel(3));
        assert!(!ports.cancel(3));
        assert_eq!(ports.queuing_status(b, rx).unwrap().waiting_processes, 0);
        // A timed-out sender's message is discarded.
        for i in 0..5u8 {
            ports.send_queuing(a, tx, &[i], 100, 0, 0, no_completion);
        }
        assert_eq!(
            ports.send_queuing(a, tx, b"late", 100, 20, 4, no_completion),
            Outcome::Parked
        );
        assert_eq!(ports.next_deadline(), Some(120));
        // The next operation on the channel expires the overdue sender before serving.
        let out = ports.receive_queuing(b, rx, 120, 0, 5, &mut buf, collect(&mut done));
        assert_eq!(
            out,
            Outcome::Done {
                code: ReturnCode::NoError,
                len: 1
            }
        );
        assert_eq!(done, vec![(4, tx, ReturnCode::TimedOut, vec![])]);
        assert_eq!(ports.queuing_status(a, tx).unwrap().nb_message, 1);
        assert_eq!(ports.queuing_status(b, rx).unwrap().nb_message, 3);
    });
}

#[test]
fn overdue_receiver_is_not_served() {
    with_ports(|ports, [a, _, tx, b, _, _, rx]| {
        let mut buf = [0u8; 32];
        ports.receive_queuing(b, rx, 0, 10, 1, &mut buf, no_completion);
        let mut done = Done::new();
        assert_eq!(
            ports.send_queuing(a, tx, b"m", 10, 0, 2, collect(&mut done)),
            sent()
        );
        assert_eq!(done, vec![(1, rx, ReturnCode::TimedOut, vec![])]);
        assert_eq!(ports.queuing_status(b, rx).unwrap().nb_message, 1);
    });
}

#[test]
fn waiter_bound() {
    with_ports(|ports, [a, _, tx, b, _, _, rx]| {
        let mut buf = [0u8; 32];
        for t in 0..MAX_WAITERS as u64 {
            assert_eq!(
                ports.receive_queuing(b, rx, 0, TIMEOUT_INFINITE, t, &mut buf, no_completion),
                Outcome::Parked
            );
        }
        assert_eq!(
            ports.receive_queuing(b, rx, 0, TIMEOUT_INFINITE, 99, &mut buf, no_completion),
            failed(ReturnCode::InvalidConfig)
        );
        // Time-out 0 still answers NOT_AVAILABLE.
        assert_eq!(
            ports.receive_queuing(b, rx, 0, 0, 99, &mut buf, no_completion),
            failed(ReturnCode::NotAvailable)
        );
        // Serve them all in order; then senders fill the list.
        let mut done = Done::new();
        for t in 0..MAX_WAITERS as u64 {
            ports.send_queuing(a, tx, &[t as u8], 0, 0, 1000, collect(&mut done));
        }
        let tokens: Vec<u64> = done.iter().map(|d| d.0).collect();
        assert_eq!(tokens, (0..MAX_WAITERS as u64).collect::<Vec<_>>());
        for _ in 0..5 {
            ports.send_queuing(a, tx, b"f", 0, 0, 0, no_completion);
        }
        for t in 0..MAX_WAITERS as u64 {
            assert_eq!(
                ports.send_queuing(a, tx, b"w", 0, 1, t, no_completion),
                Outcome::Parked
            );
        }
        assert_eq!(
            ports.send_queuing(a, tx, b"w", 0, 1, 99, no_completion),
            failed(ReturnCode::InvalidConfig)
        );
        assert_eq!(
            ports.queuing_status(a, tx).unwrap().waiting_processes,
            MAX_WAITERS as u32
        );
    });
}

#[test]
fn reset_of_destination() {
    with_ports(|ports, [a, _, tx, b, _, _, rx]| {
        let mut buf = [0u8; 32];
        for i in 0..5u8 {
            ports.send_queuing(a, tx, &[i], 0, 0, 0, no_completion);
        }
        ports.send_queuing(a, tx, &[5], 0, TIMEOUT_INFINITE, 50, no_completion);
        ports.send_queuing(a, tx, &[6], 0, TIMEOUT_INFINITE, 60, no_completion);
        let mut done = Done::new();
        ports.reset_partition(b, collect(&mut done));
        // The destination's 3 messages are gone; the source's 2 move in, and the two parked
        // senders fit.
        assert_eq!(
            done,
            vec![
                (50, tx, ReturnCode::NoError, vec![]),
                (60, tx, ReturnCode::NoError, vec![])
            ]
        );
        let mut got = Vec::new();
        while let Outcome::Done { len, .. } =
            ports.receive_queuing(b, rx, 0, 0, 0, &mut buf, no_completion)
        {
            if len == 0 {
                break;
            }
            got.push(buf[0]);
        }
        assert_eq!(got, vec![3, 4, 5, 6]);
        // Parked receivers of the restarted partition are dropped silently.
        ports.receive_queuing(b, rx, 0, TIMEOUT_INFINITE, 1, &mut buf, no_completion);
        ports.reset_partition(b, no_completion);
        assert_eq!(ports.queuing_status(b, rx).unwrap().waiting_processes, 0);
        assert_eq!(
            ports.send_queuing(a, tx, b"q", 0, 0, 0, no_completion),
            sent()
        );
        assert_eq!(ports.queuing_status(b, rx).unwrap().nb_message, 1);
    });
}

#[test]
fn reset_of_source() {
    with_ports(|ports, [a, _, tx, b, _, _, rx]| {
        let mut buf = [0u8; 32];
        for i in 0..5u8 {
            ports.send_queuing(a, tx, &[i], 0, 0, 0, no_completion);
        }
        ports.send_queuing(a, tx, &[5], 0, TIMEOUT_INFINITE, 50, no_completion);
        ports.reset_partition(a, no_completion);
        // The parked sender is dropped, the 2 messages still in the source port too; the 3
        // delivered ones stay.
        assert_eq!(ports.queuing_status(a, tx).unwrap().nb_message, 0);
        assert_eq!(ports.queuing_status(a, tx).unwrap().waiting_processes, 0);
        assert_eq!(ports.queuing_status(b, rx).unwrap().nb_message, 3);
        let mut got = Vec::new();
        while let Outcome::Done {
            code: ReturnCode::NoError,
            ..
        } = ports.receive_queuing(b, rx, 0, 0, 0, &mut buf, no_completion)
        {
            got.push(buf[0]);
        }
        assert_eq!(got, vec![0, 1, 2]);
        // A receiver of the other partition keeps waiting through the source's restart.
        ports.receive_queuing(b, rx, 0, TIMEOUT_INFINITE, 9, &mut buf, no_completion);
        ports.reset_partition(a, no_completion);
        let mut done = Done::new();
        ports.send_queuing(a, tx, b"again", 1, 0, 0, collect(&mut done));
        assert_eq!(done, vec![(9, rx, ReturnCode::NoError, b"again".to_vec())]);
    });
}

#[test]
fn clear_queuing_port() {
    with_ports(|ports, [a, _, tx, b, _, _, rx]| {
        let mut buf = [0u8; 32];
        for i in 0..5u8 {
            ports.send_queuing(a, tx, &[i], 0, 0, 0, no_completion);
        }
        ports.send_queuing(a, tx, &[5], 0, 100, 50, no_completion);
        let mut done = Done::new();
        assert_eq!(
            ports.clear_queuing(b, rx, 1, collect(&mut done)),
            ReturnCode::NoError
        );
        assert_eq!(done, vec![(50, tx, ReturnCode::NoError, vec![])]);
        assert_eq!(ports.queuing_status(b, rx).unwrap().nb_message, 3);
        assert_eq!(ports.queuing_status(a, tx).unwrap().nb_message, 0);
        ports.receive_queuing(b, rx, 1, 0, 0, &mut buf, no_completion);
        assert_eq!(buf[0], 3);
    });
}

#[test]
fn loopback_channel_in_one_partition() {
    let text = with(&[
        (
            "# a",
            r#"ports.tx = { kind = "queuing", direction = "out", size = 4, depth = 1 }
ports.rx = { kind = "queuing", direction = "in", size = 4, depth = 1 }"#,
        ),
        (
            "# tail",
            "[[channels]]\nkind = \"queuing\"\nfrom = \"a.tx\"\nto = \"a.rx\"",
        ),
    ]);
    let bytes = blob(&text);
    let system = decode(&bytes).unwrap();
    let (a, tx) = port(&system, "a", "tx");
    let (_, rx) = port(&system, "a", "rx");
    let mut arena = vec![0u8; arena_size(&system)];
    let mut ports = Ports::new(&system, &mut arena).unwrap();
    ports.send_queuing(a, tx, b"1", 0, 0, 0, no_completion);
    ports.send_queuing(a, tx, b"2", 0, 0, 0, no_completion);
    ports.send_queuing(a, tx, b"3", 0, TIMEOUT_INFINITE, 3, no_completion);
    ports.reset_partition(a, no_completion);
    ports.check_invariants();
    assert_eq!(ports.queuing_status(a, rx).unwrap().nb_message, 0);
    assert_eq!(ports.queuing_status(a, tx).unwrap().waiting_processes, 0);
    let mut buf = [0u8; 4];
    assert_eq!(
        ports.receive_queuing(a, rx, 0, 0, 0, &mut buf, no_completion),
        failed(ReturnCode::NotAvailable)
    );
}

#[test]
fn table_size_stays_small() {
    // syssw keeps `Ports` on its 64 KiB stack or in its data: the tables must stay small.
    assert!(core::mem::size_of::<Ports<'_>>() <= 24 * 1024);
}

// ---------------------------------------------------------------------------------------
// Property tests: a queuing channel against a model built on VecDeque.

#[derive(Clone, Copy, Debug)]
enum Wait {
    Poll,
    For(u64),
    Forever,
}

impl Wait {
    fn ns(self) -> u64 {
        match self {
            Wait::Poll => 0,
            Wait::For(t) => t,
            Wait::Forever => TIMEOUT_INFINITE,
        }
    }
}

#[derive(Clone, Debug)]
enum Op {
    Send { len: usize, wait: Wait },
    Receive { wait: Wait },
    Advance(u64),
    Expire,
    Clear,
    ResetSource,
    ResetDestination,
    Cancel(u64),
    Status,
}

fn wait() -> impl Strategy<Value = Wait> {
    prop_oneof![
        2 => Just(Wait::Poll),
        3 => (1u64..40).prop_map(Wait::For),
        1 => Just(Wait::Forever),
    ]
}

fn op(size: usize) -> impl Strategy<Value = Op> {
    prop_oneof![
        6 => (1..=size, wait()).prop_map(|(len, wait)| Op::Send { len, wait }),
        6 => wait().prop_map(|wait| Op::Receive { wait }),
        3 => (0u64..25).prop_map(Op::Advance),
        1 => Just(Op::Expire),
        1 => Just(Op::Clear),
        1 => Just(Op::ResetSource),
        1 => Just(Op::ResetDestination),
        1 => (0u64..64).prop_map(Op::Cancel),
        1 => Just(Op::Status),
    ]
}

struct ModelWaiter {
    token: u64,
    deadline: u64,
    msg: Vec<u8>,
}

/// The specification, written as plainly as possible.
struct Model {
    src_depth: usize,
    dst_depth: usize,
    queue: VecDeque<Vec<u8>>,
    senders: VecDeque<ModelWaiter>,
    receivers: VecDeque<ModelWaiter>,
}

impl Model {
    fn capacity(&self) -> usize {
        self.src_depth + self.dst_depth
    }

    fn expire(&mut self, now: u64, tx: usize, rx: usize, done: &mut Done) {
        for (list, port) in [(&mut self.senders, tx), (&mut self.receivers, rx)] {
            list.retain(|w| {
                let over = w.deadline != NEVER && w.deadline <= now;
                if over {
                    done.push((w.token, port, ReturnCode::TimedOut, vec![]));
                }
                !over
            });
        }
    }

    fn admit(&mut self, tx: usize, done: &mut Done) {
        while self.queue.len() < self.capacity() {
            let Some(w) = self.senders.pop_front() else {
                break;
            };
            self.queue.push_back(w.msg);
            done.push((w.token, tx, ReturnCode::NoError, vec![]));
        }
    }

    fn next_deadline(&self) -> Option<u64> {
        self.senders
            .iter()
            .chain(&self.receivers)
            .map(|w| w.deadline)
            .filter(|&d| d != NEVER)
            .min()
    }
}

fn deadline_of(now: u64, wait: Wait) -> u64 {
    match wait {
        Wait::Forever => NEVER,
        w => now + w.ns(),
    }
}

fn run_queuing(src_depth: usize, dst_depth: usize, ops: &[Op]) {
    const SIZE: usize = 6;
    let text = with(&[
        (
            "# a",
            &std::format!(
                r#"ports.tx = {{ kind = "queuing", direction = "out", size = {SIZE}, depth = {src_depth} }}"#
            ),
        ),
        (
            "# b",
            &std::format!(
                r#"ports.rx = {{ kind = "queuing", direction = "in", size = {SIZE}, depth = {dst_depth} }}"#
            ),
        ),
        (
            "# tail",
            "[[channels]]\nkind = \"queuing\"\nfrom = \"a.tx\"\nto = \"b.rx\"",
        ),
    ]);
    let bytes = blob(&text);
    let system = decode(&bytes).unwrap();
    let (a, tx) = port(&system, "a", "tx");
    let (b, rx) = port(&system, "b", "rx");
    let mut arena = vec![0u8; arena_size(&system)];
    let mut ports = Ports::new(&system, &mut arena).unwrap();
    let mut model = Model {
        src_depth,
        dst_depth,
        queue: VecDeque::new(),
        senders: VecDeque::new(),
        receivers: VecDeque::new(),
    };
    let mut now = 0u64;
    for (i, op) in ops.iter().enumerate() {
        let token = i as u64;
        let mut got = Done::new();
        let mut want = Done::new();
        match *op {
            Op::Send { len, wait } => {
                let msg: Vec<u8> = (0..len).map(|k| (i * 7 + k) as u8).collect();
                let out = ports.send_queuing(a, tx, &msg, now, wait.ns(), token, collect(&mut got));
                model.expire(now, tx, rx, &mut want);
                let expect = if let Some(r) = model.receivers.pop_front() {
                    want.push((r.token, rx, ReturnCode::NoError, msg.clone()));
                    sent()
                } else if model.senders.is_empty() && model.queue.len() < model.capacity() {
                    model.queue.push_back(msg);
                    sent()
                } else if let Wait::Poll = wait {
                    failed(ReturnCode::NotAvailable)
                } else if model.senders.len() == MAX_WAITERS {
                    failed(ReturnCode::InvalidConfig)
                } else {
                    model.senders.push_back(ModelWaiter {
                        token,
                        deadline: deadline_of(now, wait),
                        msg,
                    });
                    Outcome::Parked
                };
                assert_eq!(out, expect, "op {i}: {op:?}");
            }
            Op::Receive { wait } => {
                let mut buf = [0u8; SIZE];
                let out = ports.receive_queuing(
                    b,
                    rx,
                    now,
                    wait.ns(),
                    token,
                    &mut buf,
                    collect(&mut got),
                );
                model.expire(now, tx, rx, &mut want);
                if let Some(m) = model.queue.pop_front() {
                    model.admit(tx, &mut want);
                    assert_eq!(
                        out,
                        Outcome::Done {
                            code: ReturnCode::NoError,
                            len: m.len()
                        },
                        "op {i}: {op:?}"
                    );
                    assert_eq!(&buf[..m.len()], &m[..]);
                } else {
                    let expect = if let Wait::Poll = wait {
                        failed(ReturnCode::NotAvailable)
                    } else if model.receivers.len() == MAX_WAITERS {
                        failed(ReturnCode::InvalidConfig)
                    } else {
                        model.receivers.push_back(ModelWaiter {
                            token,
                            deadline: deadline_of(now, wait),
                            msg: vec![],
                        });
                        Outcome::Parked
                    };
                    assert_eq!(out, expect, "op {i}: {op:?}");
                }
            }
            Op::Advance(dt) => now += dt,
            Op::Expire => {
                let next = ports.expire(now, collect(&mut got));
                model.expire(now, tx, rx, &mut want);
                assert_eq!(next, model.next_deadline());
            }
            Op::Clear => {
                assert_eq!(
                    ports.clear_queuing(b, rx, now, collect(&mut got)),
                    ReturnCode::NoError
                );
                model.expire(now, tx, rx, &mut want);
                let n = model.queue.len().min(dst_depth);
                model.queue.drain(..n);
                model.admit(tx, &mut want);
            }
            Op::ResetSource => {
                ports.reset_partition(a, collect(&mut got));
                model.senders.clear();
                model.queue.truncate(dst_depth);
            }
            Op::ResetDestination => {
                ports.reset_partition(b, collect(&mut got));
                model.receivers.clear();
                let n = model.queue.len().min(dst_depth);
                model.queue.drain(..n);
                model.admit(tx, &mut want);
            }
            Op::Cancel(t) => {
                let before = model.senders.len() + model.receivers.len();
                model.senders.retain(|w| w.token != t);
                model.receivers.retain(|w| w.token != t);
                let found = before != model.senders.len() + model.receivers.len();
                assert_eq!(ports.cancel(t), found);
            }
            Op::Status => {}
        }
        assert_eq!(got, want, "completions of op {i}: {op:?}");
        ports.check_invariants();
        let (s, d) = (
            ports.queuing_status(a, tx).unwrap(),
            ports.queuing_status(b, rx).unwrap(),
        );
        let count = model.queue.len();
        assert_eq!(
            s.nb_message as usize,
            count.saturating_sub(dst_depth),
            "op {i}"
        );
        assert_eq!(d.nb_message as usize, count.min(dst_depth), "op {i}");
        assert_eq!(s.waiting_processes as usize, model.senders.len(), "op {i}");
        assert_eq!(
            d.waiting_processes as usize,
            model.receivers.len(),
            "op {i}"
        );
        assert_eq!(ports.next_deadline(), model.next_deadline(), "op {i}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn queuing_port_matches_the_model(
        src_depth in 1usize..4,
        dst_depth in 1usize..4,
        ops in proptest::collection::vec(op(6), 1..120),
    ) {
        run_queuing(src_depth, dst_depth, &ops);
    }

    /// Sampling: a read returns the last write, VALID exactly while its age is within the
    /// destination's refresh period, and NO_ACTION before any write since the reader's
    /// last reset.
    #[test]
    fn sampling_validity(
        refresh_us in 1u64..50,
        steps in proptest::collection::vec((0u8..4, 0u64..80_000, 1usize..=8), 1..80),
    ) {
        let text = with(&[
            ("# a", r#"ports.out = { kind = "sampling", direction = "out", size = 8 }"#),
            ("# b", &std::format!(
                r#"ports.in = {{ kind = "sampling", direction = "in", size = 8, refresh = "{refresh_us}us" }}"#
            )),
            ("# tail", "[[channels]]\nkind = \"sampling\"\nfrom = \"a.out\"\nto = \"b.in\""),
        ]);
        let bytes = blob(&text);
        let system = decode(&bytes).unwrap();
        let (a, out) = port(&system, "a", "out");
        let (b, inp) = port(&system, "b", "in");
        let mut arena = vec![0u8; arena_size(&system)];
        let mut ports = Ports::new(&system, &mut arena).unwrap();
        let refresh = refresh_us * 1000;
        let mut now = 0u64;
        let mut last: Option<(Vec<u8>, u64)> = None;
        let mut visible = false;
        for (i, (kind, dt, len)) in steps.into_iter().enumerate() {
            now += dt;
            match kind {
                0 => {
                    let msg: Vec<u8> = (0..len).map(|k| (i + k) as u8).collect();
                    prop_assert_eq!(ports.write_sampling(a, out, &msg, now), ReturnCode::NoError);
                    last = Some((msg, now));
                    visible = true;
                }
                1 | 2 => {
                    let mut buf = [0u8; 8];
                    let s = ports.read_sampling(b, inp, now, &mut buf);
                    match (&last, visible) {
                        (Some((msg, at)), true) => {
                            let valid = now - at <= refresh;
                            prop_assert_eq!(s.code, ReturnCode::NoError);
                            prop_assert_eq!(&buf[..s.len], &msg[..]);
                            prop_assert_eq!(s.validity == Validity::Valid, valid);
                            prop_assert_eq!(
                                ports.sampling_status(b, inp).unwrap().last_msg_validity,
                                s.validity
                            );
                        }
                        _ => {
                            prop_assert_eq!(s.code, ReturnCode::NoAction);
                            prop_assert_eq!(s.len, 0);
                        }
                    }
                }
                _ => {
                    ports.reset_partition(b, no_completion);
                    visible = false;
                }
            }
        }
    }
}

// ---------------------------------------------------------------- PRIORITY discipline

/// Queuing `a.ptx` (8 bytes, depth 1, `send`) -> `b.prx` (8 bytes, depth 1, `receive`).
fn with_priority_ports(send: &str, receive: &str, f: impl FnOnce(&mut Ports<'_>, [usize; 4])) {
    let text = with(&[
        (
            "# a",
            &std::format!(
                r#"ports.ptx = {{ kind = "queuing", direction = "out", size = 8, depth = 1, discipline = "{send}" }}"#
            ),
        ),
        (
            "# b",
            &std::format!(
                r#"ports.prx = {{ kind = "queuing", direction = "in", size = 8, depth = 1, discipline = "{receive}" }}"#
            ),
        ),
        (
            "# tail",
            r#"[[channels]]
kind = "queuing"
from = "a.ptx"
to = "b.prx""#,
        ),
    ]);
    let bytes = blob(&text);
    let system = decode(&bytes).unwrap();
    let (a, tx) = port(&system, "a", "ptx");
    let (b, rx) = port(&system, "b", "prx");
    let mut arena = vec![0u8; arena_size(&system)];
    let mut ports = Ports::new(&system, &mut arena).unwrap();
    f(&mut ports, [a, tx, b, rx]);
    ports.check_invariants();
}

fn waiter(token: u64, priority: u8) -> Waiter {
    Waiter { token, priority }
}

/// Tokens 1..=4 wait with priorities 10, 30, 20, 30.
const ARRIVALS: [(u64, u8); 4] = [(1, 10), (2, 30), (3, 20), (4, 30)];

#[test]
fn priority_receivers_are_served_highest_first_fifo_among_equals() {
    for (discipline, order) in [("priority", [2, 4, 3, 1]), ("fifo", [1, 2, 3, 4])] {
        with_priority_ports("fifo", discipline, |ports, [a, tx, b, rx]| {
            let mut buf = [0u8; 8];
            for (token, priority) in ARRIVALS {
                let parked = ports.receive_queuing(
                    b,
                    rx,
                    0,
                    100 * MS,
                    waiter(token, priority),
                    &mut buf,
                    no_completion,
                );
                assert_eq!(parked, Outcome::Parked);
            }
            assert_eq!(ports.queuing_status(b, rx).unwrap().waiting_processes, 4);
            let mut done = Done::new();
            for message in [b"m1", b"m2", b"m3", b"m4"] {
                assert_eq!(
                    ports.send_queuing(a, tx, message, MS, 0, 99, collect(&mut done)),
                    sent()
                );
            }
            let served: Vec<(u64, Vec<u8>)> = done
                .into_iter()
                .map(|(token, _, _, m)| (token, m))
                .collect();
            let expected: Vec<(u64, Vec<u8>)> = order
                .iter()
                .zip([b"m1", b"m2", b"m3", b"m4"])
                .map(|(&token, m)| (token, m.to_vec()))
                .collect();
            assert_eq!(served, expected, "{discipline} receivers");
        });
    }
}

#[test]
fn priority_senders_enter_highest_first_fifo_among_equals() {
    for (discipline, order) in [("priority", [2u8, 4, 3, 1]), ("fifo", [1, 2, 3, 4])] {
        with_priority_ports(discipline, "fifo", |ports, [a, tx, b, rx]| {
            // Capacity 2 (depth 1 + 1): full after two sends.
            for message in [b"x", b"y"] {
                assert_eq!(
                    ports.send_queuing(a, tx, message, 0, 0, 99, no_completion),
                    sent()
                );
            }
            for (token, priority) in ARRIVALS {
                let message = [b'0' + token as u8];
                let parked = ports.send_queuing(
                    a,
                    tx,
                    &message,
                    0,
                    TIMEOUT_INFINITE,
                    waiter(token, priority),
                    no_completion,
                );
                assert_eq!(parked, Outcome::Parked);
            }
            // Each receive makes room for the next sender by the discipline.
            let mut admitted = Vec::new();
            let mut received = Vec::new();
            let mut buf = [0u8; 8];
            for _ in 0..6 {
                let mut done = Done::new();
                match ports.receive_queuing(b, rx, MS, 0, 98, &mut buf, collect(&mut done)) {
                    Outcome::Done {
                        code: ReturnCode::NoError,
                        len,
                    } => received.push(buf[..len].to_vec()),
                    other => panic!("receive: {other:?}"),
                }
                admitted.extend(done.iter().map(|(token, ..)| *token as u8));
            }
            assert_eq!(admitted, order, "{discipline} senders");
            let mut expected = vec![b"x".to_vec(), b"y".to_vec()];
            expected.extend(order.iter().map(|&t| vec![b'0' + t]));
            assert_eq!(
                received, expected,
                "{discipline}: messages in admission order"
            );
        });
    }
}

#[test]
fn a_priority_waiter_times_out_and_a_cancel_keeps_the_order() {
    with_priority_ports("fifo", "priority", |ports, [a, tx, b, rx]| {
        let mut buf = [0u8; 8];
        for (token, priority, timeout) in [
            (1, 10, TIMEOUT_INFINITE),
            (2, 30, 5 * MS),
            (3, 20, TIMEOUT_INFINITE),
            (4, 25, TIMEOUT_INFINITE),
        ] {
            let parked = ports.receive_queuing(
                b,
                rx,
                0,
                timeout,
                waiter(token, priority),
                &mut buf,
                no_completion,
            );
            assert_eq!(parked, Outcome::Parked);
        }
        assert!(ports.cancel(4));
        let mut done = Done::new();
        assert_eq!(ports.expire(5 * MS, collect(&mut done)), None);
        assert_eq!(done, vec![(2, rx, ReturnCode::TimedOut, vec![])]);
        let mut done = Done::new();
        for message in [b"p", b"q"] {
            assert_eq!(
                ports.send_queuing(a, tx, message, 6 * MS, 0, 99, collect(&mut done)),
                sent()
            );
        }
        let tokens: Vec<u64> = done.iter().map(|(token, ..)| *token).collect();
        assert_eq!(tokens, [3, 1]);
    });
}

#[test]
fn the_longest_messages_keep_their_length() {
    // 64 KiB does not fit a 16-bit length: each queued message keeps its 32-bit one.
    let text = with(&[
        (
            "# a",
            r#"ports.tx = { kind = "queuing", direction = "out", size = "64KiB", depth = 1 }"#,
        ),
        (
            "# b",
            r#"ports.rx = { kind = "queuing", direction = "in", size = "64KiB", depth = 2 }"#,
        ),
        (
            "# tail",
            r#"[[channels]]
kind = "queuing"
from = "a.tx"
to = "b.rx""#,
        ),
    ]);
    let bytes = blob(&text);
    let system = decode(&bytes).unwrap();
    let mut arena = vec![0u8; arena_size(&system)];
    let mut ports = Ports::new(&system, &mut arena).unwrap();
    let (a, tx) = port(&system, "a", "tx");
    let (b, rx) = port(&system, "b", "rx");
    let longest: Vec<u8> = (0..65_536).map(|i| (i % 251) as u8).collect();
    for len in [65_536, 65_535, 4097] {
        let out = ports.send_queuing(a, tx, &longest[..len], 0, 0, 1, no_completion);
        assert_eq!(out, sent(), "{len}");
        let mut buf = vec![0u8; 65_536];
        let got = ports.receive_queuing(b, rx, 0, 0, 2, &mut buf, no_completion);
        assert_eq!(
            got,
            Outcome::Done {
                code: ReturnCode::NoError,
                len
            }
        );
        assert_eq!(&buf[..len], &longest[..len]);
    }
    let too_long = vec![0u8; 65_537];
    assert_eq!(
        ports.send_queuing(a, tx, &too_long, 0, 0, 1, no_completion),
        failed(ReturnCode::InvalidConfig)
    );
}

#[test]
fn a_doorbell_rings_once_for_the_messages_that_entered_the_fifo() {
    with_ports(|ports, [a, out, tx, b, inp, _, rx]| {
        let rung = |ports: &mut Ports<'_>| {
            let mut bells = Vec::new();
            ports.take_rung(|bell| bells.push(bell));
            bells
        };
        let bell = Doorbell {
            token: 42,
            bits: 1 << 9,
        };
        // Only the partition's own queuing destination port has one.
        assert_eq!(ports.set_doorbell(a, rx, 42, 1), ReturnCode::InvalidParam);
        assert_eq!(ports.set_doorbell(a, tx, 42, 1), ReturnCode::InvalidMode);
        assert_eq!(ports.set_doorbell(a, out, 42, 1), ReturnCode::InvalidParam);
        assert_eq!(ports.set_doorbell(b, inp, 42, 1), ReturnCode::InvalidParam);
        assert_eq!(ports.set_doorbell(b, 999, 42, 1), ReturnCode::InvalidParam);
        assert_eq!(
            ports.set_doorbell(b, rx, 42, bell.bits),
            ReturnCode::NoError
        );
        assert!(rung(ports).is_empty(), "an empty port does not ring");
        for m in [&b"one"[..], b"two"] {
            assert_eq!(ports.send_queuing(a, tx, m, 0, 0, 1, no_completion), sent());
        }
        assert_eq!(rung(ports), vec![bell], "once for two messages");
        assert!(rung(ports).is_empty());
        // A message handed to a waiting receiver does not ring.
        let mut buf = [0u8; 32];
        for _ in 0..2 {
            ports.receive_queuing(b, rx, 0, 0, 7, &mut buf, no_completion);
        }
        assert_eq!(
            ports.receive_queuing(b, rx, 0, TIMEOUT_INFINITE, 7, &mut buf, no_completion),
            Outcome::Parked
        );
        let mut done = Done::new();
        ports.send_queuing(a, tx, b"handed", 0, 0, 1, collect(&mut done));
        assert_eq!(done.len(), 1);
        assert!(rung(ports).is_empty());
        // Setting it on a port that holds messages rings at once.
        ports.send_queuing(a, tx, b"queued", 0, 0, 1, no_completion);
        assert_eq!(ports.set_doorbell(b, rx, 42, 0), ReturnCode::NoError);
        assert!(rung(ports).is_empty(), "removed");
        ports.send_queuing(a, tx, b"unheard", 0, 0, 1, no_completion);
        assert!(rung(ports).is_empty());
        let other = Doorbell { token: 43, bits: 1 };
        assert_eq!(ports.set_doorbell(b, rx, 43, 1), ReturnCode::NoError);
        assert_eq!(rung(ports), vec![other]);
        // Fill the FIFO and park a sender: a receive admits it, which rings.
        while ports.send_queuing(a, tx, b"x", 0, 0, 1, no_completion) == sent() {}
        assert_eq!(
            ports.send_queuing(a, tx, b"parked", 0, TIMEOUT_INFINITE, 5, no_completion),
            Outcome::Parked
        );
        rung(ports);
        let mut done = Done::new();
        ports.receive_queuing(b, rx, 0, 0, 7, &mut buf, collect(&mut done));
        assert_eq!(done.len(), 1);
        assert_eq!(rung(ports), vec![other]);
        // A restart of the destination ends it.
        ports.reset_partition(b, |_| {});
        ports.send_queuing(a, tx, b"after", 0, 0, 1, |_| {});
        assert!(rung(ports).is_empty());
    });
}
