use super::*;
use crate::testsys::{blob, with};
use ErrorCode as E;
use HealthAction as A;
use config::decode;
use std::string::String;
use std::vec::Vec;

fn fault(vector: u64) -> Fault {
    Fault {
        vector,
        error_code: 0,
        address: 0,
        rip: 0x40_1000,
        rsp: 0x7000_0000,
        rax: 0,
    }
}

const GUARD: Range<u64> = 0x6fff_0000..0x7000_0000;

#[test]
fn exceptions_map_to_arinc_errors() {
    let expected: [(u64, E); 32] = [
        (0, E::NumericError),
        (1, E::IllegalRequest),
        (2, E::HardwareFault),
        (3, E::IllegalRequest),
        (4, E::NumericError),
        (5, E::MemoryViolation),
        (6, E::IllegalRequest),
        (7, E::IllegalRequest),
        (8, E::HardwareFault),
        (9, E::HardwareFault),
        (10, E::IllegalRequest),
        (11, E::MemoryViolation),
        (12, E::MemoryViolation),
        (13, E::IllegalRequest),
        (14, E::MemoryViolation),
        (15, E::HardwareFault),
        (16, E::NumericError),
        (17, E::MemoryViolation),
        (18, E::HardwareFault),
        (19, E::NumericError),
        (20, E::HardwareFault),
        (21, E::IllegalRequest),
        (22, E::HardwareFault),
        (23, E::HardwareFault),
        (24, E::HardwareFault),
        (25, E::HardwareFault),
        (26, E::HardwareFault),
        (27, E::HardwareFault),
        (28, E::HardwareFault),
        (29, E::HardwareFault),
        (30, E::HardwareFault),
        (31, E::HardwareFault),
    ];
    for (vector, error) in expected {
        assert_eq!(classify(&fault(vector), GUARD), error, "vector {vector}");
    }
    assert_eq!(classify(&fault(VECTOR_SYSCALL), GUARD), E::IllegalRequest);
    assert_eq!(classify(&fault(0x42), GUARD), E::HardwareFault);
    assert_eq!(classify(&fault(u64::MAX), GUARD), E::HardwareFault);
}

#[test]
fn stack_guard_faults_are_stack_overflows() {
    let mut f = fault(14);
    f.address = GUARD.start;
    assert_eq!(classify(&f, GUARD), E::StackOverflow);
    f.address = GUARD.end - 1;
    assert_eq!(classify(&f, GUARD), E::StackOverflow);
    f.address = GUARD.end;
    assert_eq!(classify(&f, GUARD), E::MemoryViolation);
    f.address = GUARD.start - 1;
    assert_eq!(classify(&f, GUARD), E::MemoryViolation);
    // Without a guard: never a stack overflow.
    f.address = GUARD.start;
    assert_eq!(classify(&f, 0..0), E::MemoryViolation);
    // #SS: by rsp.
    let mut s = fault(12);
    s.rsp = GUARD.start + 8;
    assert_eq!(classify(&s, GUARD), E::StackOverflow);
    s.rsp = 0x8000_0000_0000_0000;
    assert_eq!(classify(&s, GUARD), E::MemoryViolation);
    // The guard matters only for #PF and #SS.
    let mut g = fault(13);
    g.address = GUARD.start;
    g.rsp = GUARD.start;
    assert_eq!(classify(&g, GUARD), E::IllegalRequest);
}

#[test]
fn fault_from_exception_message() {
    let mut m = ExceptionMessage {
        vector: 14,
        error_code: 6,
        fault_address: 0xdead_0000,
        ..Default::default()
    };
    m.registers.rip = 0x40_1000;
    m.registers.rsp = 0x7000;
    m.registers.rax = 60;
    assert_eq!(
        Fault::from_message(&m),
        Fault {
            vector: 14,
            error_code: 6,
            address: 0xdead_0000,
            rip: 0x40_1000,
            rsp: 0x7000,
            rax: 60
        }
    );
}

fn system_bytes() -> Vec<u8> {
    blob(&with(&[
        (
            "# a",
            "health.deadline_missed = \"warm_restart\"\nhealth.application_error = \"shutdown_success\"",
        ),
        (
            "# tail",
            "[health]\ndeadline_missed = \"idle\"\nmemory_violation = \"cold_restart\"\nhardware_fault = \"ignore\"\nnumeric_error = \"shutdown_success\"",
        ),
    ]))
}

#[test]
fn decisions_follow_the_tables() {
    let bytes = system_bytes();
    let system = decode(&bytes).unwrap();
    let a = system.find_partition("a").unwrap().index;
    let b = system.find_partition("b").unwrap().index;
    // The partition's own entry first.
    assert_eq!(decide(&system, Some(a), E::DeadlineMissed), A::WarmRestart);
    assert_eq!(
        decide(&system, Some(a), E::ApplicationError),
        A::ShutdownSuccess
    );
    // Then the module's.
    assert_eq!(decide(&system, Some(b), E::DeadlineMissed), A::Idle);
    assert_eq!(decide(&system, Some(a), E::MemoryViolation), A::ColdRestart);
    // Then idle.
    assert_eq!(decide(&system, Some(b), E::StackOverflow), A::Idle);
    // Module level: partition actions mean shutdown, unset means shutdown.
    assert_eq!(decide(&system, None, E::DeadlineMissed), A::Shutdown);
    assert_eq!(decide(&system, None, E::MemoryViolation), A::Shutdown);
    assert_eq!(decide(&system, None, E::PowerFail), A::Shutdown);
    assert_eq!(decide(&system, None, E::HardwareFault), A::Ignore);
    assert_eq!(decide(&system, None, E::NumericError), A::ShutdownSuccess);
    // An index the system does not have is module level.
    assert_eq!(decide(&system, Some(15), E::DeadlineMissed), A::Shutdown);
    assert_eq!(
        decide(&system, Some(usize::MAX), E::HardwareFault),
        A::Ignore
    );
    // Every error of every partition resolves exactly like HealthTable::resolve.
    for p in system.partitions() {
        for e in E::ALL {
            assert_eq!(
                decide(&system, Some(p.index), e),
                HealthTable::resolve(Some(&p.health), &system.health(), e)
            );
        }
    }
}

fn line(system: &SystemView<'_>, record: &Record) -> String {
    let mut s = String::new();
    write_log_line(&mut s, system, record).unwrap();
    s
}

#[test]
fn log_line_format() {
    let bytes = system_bytes();
    let system = decode(&bytes).unwrap();
    let a = system.find_partition("a").unwrap().index;
    let mut hm = HealthMonitor::new();
    let mut f = fault(14);
    f.error_code = 6;
    f.address = 0xdead_0000;
    let r = hm.report(
        &system,
        12_345_678,
        ErrorEvent {
            partition: Some(a),
            error: E::MemoryViolation,
            detail: Detail::Fault(f),
        },
    );
    assert_eq!(
        line(&system, &r),
        "health: t=12.345ms partition=a error=memory_violation detail=#PF,error=0x6,address=0xdead0000,rip=0x401000 action=cold_restart"
    );
    let r = hm.report(
        &system,
        5_000,
        ErrorEvent {
            partition: None,
            error: E::PowerFail,
            detail: Detail::None,
        },
    );
    assert_eq!(
        line(&system, &r),
        "health: t=0.005ms partition=- error=power_fail detail=- action=shutdown"
    );
    let r = Record {
        time: 1_000_000_000_000,
        partition: Some(a),
        error: E::ApplicationError,
        detail: Detail::Code(0x2a),
        action: A::ShutdownSuccess,
    };
    assert_eq!(
        line(&system, &r),
        "health: t=1000000.000ms partition=a error=application_error detail=0x2a action=shutdown_success"
    );
    let mut s = fault(VECTOR_SYSCALL);
    s.rax = 60;
    let r = Record {
        detail: Detail::Fault(s),
        ..r
    };
    assert!(line(&system, &r).contains(" detail=syscall,number=60,rip=0x401000 "));
    let r = Record {
        detail: Detail::Fault(fault(9)),
        ..r
    };
    assert!(line(&system, &r).contains(" detail=vector=9,error=0x0,address=0x0,rip=0x401000 "));
    let r = Record {
        detail: Detail::Text(Text::new(b"tank \"low\"\\\n\xff")),
        ..r
    };
    assert!(line(&system, &r).contains(r#" detail="tank\x20\"low\"\\\x0a\xff" "#));
    let r = Record {
        detail: Detail::Dma(DmaFault {
            source: 4 << 3,
            address: 0x7f_0000_0000,
            write: true,
            reason: 5,
        }),
        ..r
    };
    assert!(
        line(&system, &r)
            .contains(" detail=dma,device=00:04.0,write,address=0x7f00000000,reason=5 ")
    );
    // A record naming a partition the system does not have prints `-`.
    let r = Record {
        partition: Some(14),
        ..r
    };
    assert!(line(&system, &r).contains(" partition=- "));
}

#[test]
fn text_is_cut_at_the_limit() {
    let long = [b'x'; 100];
    let t = Text::new(&long);
    assert_eq!(t.as_bytes().len(), DETAIL_TEXT_MAX);
    assert_eq!(Text::new(b"").as_bytes(), b"");
    assert_eq!(std::format!("{}", Detail::Text(Text::new(b"ok"))), "\"ok\"");
}

#[test]
fn counters_and_ring() {
    let bytes = system_bytes();
    let system = decode(&bytes).unwrap();
    let a = system.find_partition("a").unwrap().index;
    let b = system.find_partition("b").unwrap().index;
    let mut hm = HealthMonitor::default();
    assert_eq!(hm.recent().count(), 0);
    assert_eq!(hm.last(Some(a)), None);
    for i in 0..20u64 {
        let partition = match i % 3 {
            0 => Some(a),
            1 => Some(b),
            _ => None,
        };
        let r = hm.report(
            &system,
            i,
            ErrorEvent {
                partition,
                error: E::DeadlineMissed,
                detail: Detail::Code(i),
            },
        );
        assert_eq!((r.time, r.partition), (i, partition));
    }
    assert_eq!(hm.count(Some(a)), 7);
    assert_eq!(hm.count(Some(b)), 7);
    assert_eq!(hm.count(None), 6);
    assert_eq!(hm.count(Some(99)), 0);
    assert_eq!(hm.total(), 20);
    let times: Vec<u64> = hm.recent().map(|r| r.time).collect();
    assert_eq!(times, (4..20).collect::<Vec<_>>());
    assert_eq!(hm.last(Some(a)).map(|r| r.time), Some(18));
    assert_eq!(hm.last(Some(b)).map(|r| r.time), Some(19));
    assert_eq!(hm.last(None).map(|r| r.time), Some(17));
    // The decision is recorded with the event.
    assert_eq!(hm.last(Some(a)).unwrap().action, A::WarmRestart);
    assert_eq!(hm.last(Some(b)).unwrap().action, A::Idle);
    assert_eq!(hm.last(None).unwrap().action, A::Shutdown);
    // An unknown partition index is counted and recorded as module level.
    let r = hm.report(
        &system,
        30,
        ErrorEvent {
            partition: Some(7),
            error: E::HardwareFault,
            detail: Detail::None,
        },
    );
    assert_eq!((r.partition, r.action), (None, A::Ignore));
    assert_eq!(hm.count(None), 7);
}

#[test]
fn vector_names() {
    assert_eq!(vector_name(14), Some("#PF"));
    assert_eq!(vector_name(2), Some("NMI"));
    assert_eq!(vector_name(VECTOR_SYSCALL), Some("syscall"));
    assert_eq!(vector_name(9), None);
    assert_eq!(vector_name(15), None);
    assert_eq!(vector_name(31), None);
    assert_eq!(vector_name(32), None);
}
