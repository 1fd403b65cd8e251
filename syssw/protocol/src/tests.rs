use super::*;
use proptest::prelude::*;

const NAME: &[u8] = b"sensor";
const MESSAGE: &[u8] = b"\x01\x02\x03";

/// One request of every kind, with values that use every field.
fn every_request() -> [Request<'static>; Label::COUNT] {
    [
        Request::PartitionStatus,
        Request::SetPartitionMode {
            mode: OperatingMode::WarmStart,
        },
        Request::CreatePort {
            kind: PortKind::Queuing,
            direction: Direction::In,
            discipline: Discipline::Priority,
            max_message_size: 64,
            refresh_or_depth: 4,
            name: NAME,
        },
        Request::PortId {
            kind: PortKind::Sampling,
            name: NAME,
        },
        Request::WriteSampling {
            port: 7,
            staged: 8192,
            message: MESSAGE,
        },
        Request::ReadSampling { port: 1 },
        Request::SamplingStatus { port: 2 },
        Request::SendQueuing {
            port: 3,
            timeout: 1_000_000,
            priority: 200,
            staged: 4096,
            message: MESSAGE,
        },
        Request::ReceiveQueuing {
            port: 4,
            timeout: u64::MAX,
            priority: 7,
        },
        Request::QueuingStatus { port: 5 },
        Request::ClearQueuing { port: 6 },
        Request::PortDoorbell {
            port: 6,
            bits: 1 << 9,
        },
        Request::ReportError {
            error: ErrorCode::PowerFail,
            detail: b"detail",
        },
        Request::ApplicationMessage { text: b"hello" },
        Request::SetModuleSchedule { schedule: 2 },
        Request::ModuleScheduleStatus,
        Request::ModuleScheduleId { name: NAME },
        Request::StageMessage {
            offset: 4096,
            part: MESSAGE,
        },
        Request::FetchMessage { offset: 8192 },
    ]
}

#[test]
fn every_request_round_trips() {
    let requests = every_request();
    for label in Label::ALL {
        assert!(
            requests.iter().any(|r| r.label() == label),
            "no test request for {label}"
        );
    }
    for request in requests {
        let wire = request.encode();
        assert_eq!(wire.label, request.label().code());
        assert_eq!(Request::decode(wire), Ok(request), "{request:?}");
    }
}

#[test]
fn the_documented_word_packing() {
    let wire = Request::CreatePort {
        kind: PortKind::Sampling,
        direction: Direction::Out,
        discipline: Discipline::Fifo,
        max_message_size: 8,
        refresh_or_depth: 20_000_000,
        name: NAME,
    }
    .encode();
    assert_eq!(wire.label, 10);
    assert_eq!(wire.words, [1 | 2 << 8, 8, 20_000_000]);
    assert_eq!(wire.data, NAME);
    let wire = Request::CreatePort {
        kind: PortKind::Queuing,
        direction: Direction::In,
        discipline: Discipline::Priority,
        max_message_size: 8,
        refresh_or_depth: 4,
        name: NAME,
    }
    .encode();
    assert_eq!(wire.words, [2 | 1 << 8 | 1 << 16, 8, 4]);
    let wire = Request::ReceiveQueuing {
        port: 3,
        timeout: 5,
        priority: 42,
    }
    .encode();
    assert_eq!((wire.label, wire.words), (16, [3, 5, 42]));
    let status = PartitionStatus {
        mode: OperatingMode::Normal,
        start_condition: StartCondition::HmPartitionRestart,
        index: 2,
        period_ns: 10,
        duration_ns: 3,
    };
    assert_eq!(status.to_words(), [3 | 3 << 8 | 2 << 16, 10, 3]);
}

fn wire(label: u32, words: [u64; 3]) -> Wire<'static> {
    Wire {
        label,
        words,
        data: &[],
    }
}

#[test]
fn bad_codes_are_errors_with_the_answer_syssw_gives() {
    let cases = [
        (
            wire(99, [0; 3]),
            DecodeError::UnknownLabel(99),
            ReturnCode::InvalidParam,
        ),
        (
            wire(2, [4, 0, 0]),
            DecodeError::UnknownMode(4),
            ReturnCode::InvalidParam,
        ),
        (
            wire(20, [8, 0, 0]),
            DecodeError::UnknownError(8),
            ReturnCode::InvalidParam,
        ),
        (
            wire(10, [3 | 1 << 8, 0, 0]),
            DecodeError::UnknownPortKind(3),
            ReturnCode::InvalidConfig,
        ),
        (
            wire(10, [1 | 7 << 8, 0, 0]),
            DecodeError::UnknownDirection(7),
            ReturnCode::InvalidConfig,
        ),
        (
            wire(10, [2 | 1 << 8 | 2 << 16, 0, 0]),
            DecodeError::UnknownDiscipline(2),
            ReturnCode::InvalidConfig,
        ),
        (
            wire(16, [0, 0, 256]),
            DecodeError::BadPriority(256),
            ReturnCode::InvalidParam,
        ),
        (
            wire(11, [0, 0, 0]),
            DecodeError::UnknownPortKind(0),
            ReturnCode::InvalidConfig,
        ),
        // A wide word whose low byte is a valid code is still not one.
        (
            wire(2, [0x100, 0, 0]),
            DecodeError::UnknownMode(0x100),
            ReturnCode::InvalidParam,
        ),
    ];
    for (wire, error, answer) in cases {
        assert_eq!(Request::decode(wire), Err(error));
        assert_eq!(error.return_code(), answer);
    }
}

#[test]
fn every_reply_round_trips() {
    fn check<R: ReplyWords + PartialEq + core::fmt::Debug>(reply: R) {
        assert_eq!(R::from_words(reply.to_words()), Ok(reply));
    }
    check(PartitionStatus {
        mode: OperatingMode::ColdStart,
        start_condition: StartCondition::PartitionRestart,
        index: 14,
        period_ns: 10_000_000,
        duration_ns: 2_000_000,
    });
    check(PortIdReply { port: 127 });
    check(SamplingMessage {
        len: 8,
        validity: Validity::Valid,
    });
    check(SamplingStatus {
        max_message_size: 4096,
        direction: Direction::In,
        refresh_period: 125_000_000,
        last_msg_validity: Validity::Invalid,
    });
    check(QueuingMessage { len: 0 });
    check(ScheduleIdReply { schedule: 3 });
    check(ScheduleStatus {
        last_switch: 150_000_000,
        current: 1,
        next: 0,
    });
    check(QueuingStatus {
        nb_message: 3,
        max_nb_message: 256,
        max_message_size: 64,
        direction: Direction::Out,
        waiting_processes: 2,
    });
    for code in ReturnCode::ALL {
        let expected = match code {
            ReturnCode::NoError => Ok(()),
            code => Err(code),
        };
        assert_eq!(reply_result(code.code()), Ok(expected));
    }
    assert_eq!(reply_result(7), Err(DecodeError::UnknownReturnCode(7)));
}

#[test]
fn bad_reply_words_are_errors() {
    assert!(PartitionStatus::from_words([4, 0, 0]).is_err());
    assert!(PartitionStatus::from_words([4 << 8, 0, 0]).is_err());
    assert!(SamplingMessage::from_words([1, 2, 0]).is_err());
    assert!(SamplingStatus::from_words([0, 0, 0]).is_err());
    assert!(QueuingStatus::from_words([0, 3 << 32, 0]).is_err());
}

proptest! {
    /// Hostile words never panic; whatever decodes re-encodes to a request that decodes to
    /// itself (unused words and data are dropped, nothing else changes).
    #[test]
    fn any_request_decodes_or_errs(
        label in prop_oneof![0u32..32, any::<u32>()],
        words in any::<[u64; 3]>(),
        data in proptest::collection::vec(any::<u8>(), 0..64),
    ) {
        let wire = Wire { label, words, data: &data };
        if let Ok(request) = Request::decode(wire) {
            let again = request.encode();
            prop_assert_eq!(again.label, label);
            // Data is kept where the request carries data, dropped where it has none.
            prop_assert!(again.data.is_empty() || again.data == &data[..]);
            prop_assert_eq!(Request::decode(again), Ok(request));
        }
    }

    #[test]
    fn any_reply_words_decode_or_err(words in any::<[u64; 3]>(), label in any::<u32>()) {
        fn check<R: ReplyWords + PartialEq + core::fmt::Debug>(words: [u64; 3]) {
            if let Ok(reply) = R::from_words(words) {
                assert_eq!(R::from_words(reply.to_words()), Ok(reply));
            }
        }
        check::<PartitionStatus>(words);
        check::<PortIdReply>(words);
        check::<SamplingMessage>(words);
        check::<SamplingStatus>(words);
        check::<QueuingMessage>(words);
        check::<QueuingStatus>(words);
        let _ = reply_result(label);
    }
}

#[test]
fn arinc_numbering() {
    let expected = [
        (ReturnCode::NoError, 0, "NO_ERROR"),
        (ReturnCode::NoAction, 1, "NO_ACTION"),
        (ReturnCode::NotAvailable, 2, "NOT_AVAILABLE"),
        (ReturnCode::InvalidParam, 3, "INVALID_PARAM"),
        (ReturnCode::InvalidConfig, 4, "INVALID_CONFIG"),
        (ReturnCode::InvalidMode, 5, "INVALID_MODE"),
        (ReturnCode::TimedOut, 6, "TIMED_OUT"),
    ];
    for (code, value, name) in expected {
        assert_eq!(code.code(), value);
        assert_eq!(ReturnCode::from_code(value), Some(code));
        assert_eq!(code.name(), name);
    }
    assert_eq!(ReturnCode::from_code(7), None);
    assert_eq!(ReturnCode::from_u64(u64::MAX), None);
    // ERROR_CODE_TYPE as ARINC numbers it.
    let errors = [
        ErrorCode::DeadlineMissed,
        ErrorCode::ApplicationError,
        ErrorCode::NumericError,
        ErrorCode::IllegalRequest,
        ErrorCode::StackOverflow,
        ErrorCode::MemoryViolation,
        ErrorCode::HardwareFault,
        ErrorCode::PowerFail,
    ];
    for (value, error) in errors.into_iter().enumerate() {
        assert_eq!(usize::from(error.code()), value);
    }
}
