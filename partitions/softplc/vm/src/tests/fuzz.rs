//! Property tests: `Image::parse`, `verify` and (for images that verify) the VM never panic,
//! on arbitrary bytes and on mutations of valid images.

use super::differential::random_program;
use super::*;
use crate::isa::Builtin;
use alloc::string::{String, ToString};
use proptest::prelude::*;

/// Parses, verifies and — if it verifies — runs a few cycles: must never panic.
fn exercise(bytes: &[u8]) {
    let Ok(image) = Image::parse(bytes) else {
        return;
    };
    // Accessors on unverified images must be total as well.
    for i in 0..image.pou_count().min(64) {
        let _ = image.pou(i);
    }
    for i in 0..image.var_count().min(64) {
        let _ = image.var(i);
    }
    let _ = image.source_location(u32::MAX);
    let _ = image.constant(usize::MAX);
    let Ok(verified) = verify(&image) else { return };
    let mut data = vec![0u8; image.data_size().min(1 << 20) as usize];
    let mut stack = [0u64; STACK];
    let mut calls = [CallFrame::EMPTY; CALLS];
    let mut tries = [TryFrame::EMPTY; TRIES];
    let Ok(mut vm) = Machine::new(
        verified,
        Memory {
            data: &mut data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut tries,
        },
    ) else {
        return;
    };
    for task in 0..image.task_count().min(4) {
        vm.set_watchdog_budget(task, Some(5_000));
        let _ = vm.run_cycle(task, 0);
    }
}

fn mutate(mut bytes: Vec<u8>, edits: &[(usize, u8)], cut: Option<usize>) -> Vec<u8> {
    for &(at, value) in edits {
        if !bytes.is_empty() {
            let at = at % bytes.len();
            bytes[at] = value;
        }
    }
    if let Some(cut) = cut {
        let len = bytes.len();
        bytes.truncate(cut % (len + 1));
    }
    bytes
}

/// String builtins: the library and the model's independent implementation agree on
/// random strings, positions, lengths and (sometimes invalid) addresses.
fn string_case(
    texts: &[(u16, Vec<u8>)],
    builtin_index: usize,
    picks: &[u8],
    numbers: &[i64],
) -> Result<(), TestCaseError> {
    use crate::isa::Builtin;
    let string_builtins: Vec<Builtin> = Builtin::ALL
        .iter()
        .copied()
        .filter(|b| !b.is_math())
        .collect();
    let builtin = string_builtins[builtin_index % string_builtins.len()];
    // Three string variables at 0, 40, 80 (capacity up to 32), data 124 bytes.
    let mut data = vec![0u8; 124];
    let addresses = [0u64, 40, 80, 122, 1000];
    for (slot, (capacity, text)) in texts.iter().enumerate() {
        let at = slot * 40;
        let capacity = capacity % 33;
        data[at..at + 2].copy_from_slice(&capacity.to_le_bytes());
        data[at + 2..at + 4].copy_from_slice(&(text.len() as u16).to_le_bytes());
        let n = text.len().min(36);
        data[at + 4..at + 4 + n].copy_from_slice(&text[..n]);
    }
    let mut args = Vec::new();
    for i in 0..builtin.args() {
        // Dst and string operands are addresses; numeric operands are numbers.
        let numeric = match builtin {
            Builtin::StrLeft | Builtin::StrRight | Builtin::WStrLeft | Builtin::WStrRight => i == 2,
            Builtin::StrMid | Builtin::StrDelete | Builtin::WStrMid | Builtin::WStrDelete => i >= 2,
            Builtin::StrInsert | Builtin::WStrInsert => i == 3,
            Builtin::StrReplace | Builtin::WStrReplace => i >= 3,
            Builtin::StrFromI64
            | Builtin::StrFromU64
            | Builtin::StrFromF32
            | Builtin::StrFromF64
            | Builtin::StrFromBool
            | Builtin::StrFromTime => i == 1,
            Builtin::StrFromDateTime => i >= 1,
            Builtin::StrToDateTime => i == 1,
            Builtin::DateFromParts
            | Builtin::DateSplit
            | Builtin::DateOf
            | Builtin::TodOf
            | Builtin::DayOfWeek
            | Builtin::TodFromParts => true,
            _ => false,
        };
        args.push(if numeric {
            numbers[i % numbers.len()] as u64
        } else {
            addresses[picks[i % picks.len()] as usize % addresses.len()]
        });
    }
    let mut library_data = data.clone();
    let library = crate::builtins::call(builtin, &args, &mut library_data);
    let mut model_data = data;
    let model = crate::model::string_builtin(builtin, &args, &mut model_data);
    prop_assert_eq!(library, model, "{:?} {:?}", builtin, args);
    prop_assert_eq!(library_data, model_data, "{:?} {:?}", builtin, args);
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 3000, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn string_builtins_agree_with_the_model(
        texts in proptest::collection::vec(
            (any::<u16>(), proptest::collection::vec(
                prop_oneof![Just(b'a'), Just(b'b'), Just(b' '), Just(b'1'), Just(b'-'), Just(b'_'), any::<u8>()],
                0..36,
            )),
            3,
        ),
        builtin_index in any::<usize>(),
        picks in proptest::collection::vec(any::<u8>(), 1..6),
        numbers in proptest::collection::vec(
            prop_oneof![-3i64..40, any::<i64>(), Just(i64::MIN), Just(0i64)],
            1..6,
        ),
    ) {
        string_case(&texts, builtin_index, &picks, &numbers)?;
    }

    /// Date/time literals built from the pieces they are made of: parsing agrees with the
    /// model, and what DATE_TIME_TO_STRING prints parses back to the same value.
    #[test]
    fn date_time_builtins_agree_with_the_model(
        pieces in proptest::collection::vec(
            prop_oneof![
                (0u32..3000).prop_map(|n| n.to_string()),
                Just("-".to_string()), Just(":".to_string()), Just(".".to_string()),
                Just("_".to_string()), Just(" ".to_string()), Just("#".to_string()),
                Just("D#".to_string()), Just("tod#".to_string()), Just("DT#".to_string()),
                Just("LT#".to_string()), Just("ms".to_string()), Just("S".to_string()),
                Just("h".to_string()), Just("d".to_string()), Just("us".to_string()),
                Just("2024-02-29".to_string()), Just("23:59:59.999999999".to_string()),
            ],
            0..8,
        ),
        kind in 0u64..9,
        value in prop_oneof![any::<i64>(), -4_000_000_000_000_000_000i64..4_000_000_000_000_000_000],
        parts in proptest::collection::vec(prop_oneof![-2i64..70, any::<i64>()], 4),
    ) {
        let text: String = pieces.concat();
        let mut data = vec![0u8; 200];
        data[..2].copy_from_slice(&100u16.to_le_bytes());
        data[2..4].copy_from_slice(&(text.len().min(100) as u16).to_le_bytes());
        data[4..4 + text.len().min(100)].copy_from_slice(&text.as_bytes()[..text.len().min(100)]);
        data[110..112].copy_from_slice(&80u16.to_le_bytes());
        let cases: [(Builtin, Vec<u64>); 8] = [
            (Builtin::StrToDateTime, vec![0, kind]),
            (Builtin::StrFromDateTime, vec![110, value as u64, kind]),
            (Builtin::DateFromParts, vec![(parts[0] as u64).wrapping_add(1960), parts[1] as u64, parts[2] as u64]),
            (Builtin::TodFromParts, parts.iter().map(|&p| p as u64).collect()),
            (Builtin::DateSplit, vec![value as u64]),
            (Builtin::DateOf, vec![value as u64]),
            (Builtin::TodOf, vec![value as u64]),
            (Builtin::DayOfWeek, vec![value as u64]),
        ];
        for (builtin, args) in cases {
            let mut library_data = data.clone();
            let library = crate::builtins::call(builtin, &args, &mut library_data);
            let mut model_data = data.clone();
            let model = crate::model::string_builtin(builtin, &args, &mut model_data);
            prop_assert_eq!(library, model, "{:?} {:?} {:?}", builtin, args, text);
            prop_assert_eq!(library_data, model_data, "{:?} {:?}", builtin, args);
        }
        if let Some(kind) = crate::isa::TimeKind::from_u64(kind) {
            let mut printed = String::new();
            crate::builtins::format_date_time(&mut printed, kind, value);
            let expected = match kind {
                crate::isa::TimeKind::Date | crate::isa::TimeKind::LDate => {
                    value.div_euclid(crate::builtins::NS_PER_DAY).checked_mul(crate::builtins::NS_PER_DAY)
                }
                crate::isa::TimeKind::Tod | crate::isa::TimeKind::LTod => {
                    Some(value.rem_euclid(crate::builtins::NS_PER_DAY))
                }
                _ => Some(value),
            };
            if expected.is_some() {
                prop_assert_eq!(
                    crate::builtins::parse_date_time(printed.as_bytes(), kind),
                    expected,
                    "{}",
                    printed
                );
            }
        }
    }

    #[test]
    fn parse_and_verify_never_panic_on_arbitrary_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        exercise(&bytes);
    }

    #[test]
    fn parse_and_verify_never_panic_on_arbitrary_bytes_behind_a_valid_header(
        tail in proptest::collection::vec(any::<u8>(), 0..300),
        lens in proptest::collection::vec(0u32..64, crate::image::SECTION_COUNT),
    ) {
        // A correct header with arbitrary (mostly in-bounds) sections.
        let mut bytes = Vec::new();
        bytes.extend_from_slice(b"PLCB");
        bytes.extend_from_slice(&crate::image::VERSION.to_le_bytes());
        bytes.extend_from_slice(&(crate::image::HEADER_LEN as u16).to_le_bytes());
        bytes.extend_from_slice(&256u32.to_le_bytes());
        bytes.extend_from_slice(&0u32.to_le_bytes());
        let mut offset = crate::image::HEADER_LEN as u32;
        for len in &lens {
            bytes.extend_from_slice(&offset.to_le_bytes());
            bytes.extend_from_slice(&len.to_le_bytes());
            offset += len;
        }
        bytes.extend_from_slice(&tail);
        exercise(&bytes);
    }

    #[test]
    fn parse_verify_and_run_never_panic_on_mutated_valid_images(
        seed in 0u64..1_000_000,
        edits in proptest::collection::vec((any::<usize>(), any::<u8>()), 1..6),
        cut in proptest::option::of(any::<usize>()),
    ) {
        let bytes = mutate(random_program(seed), &edits, cut);
        exercise(&bytes);
    }
}

#[test]
fn single_byte_mutations_of_a_valid_image_never_panic() {
    // Exhaustive over positions for one program, a few values each.
    let bytes = random_program(7);
    for at in 0..bytes.len() {
        for value in [0u8, 1, 0x7F, 0x80, 0xFF, bytes[at].wrapping_add(1)] {
            exercise(&mutate(bytes.clone(), &[(at, value)], None));
        }
    }
}
