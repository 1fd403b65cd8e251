//! Builtins: math accuracy against std, string functions, TIME/number formatting, and the
//! monitor API (read/force by name).

use super::*;
use crate::builtins::{self, format_time};
use crate::fmath;
use crate::image::VarType;
use crate::isa::{Builtin, MemType, Trap};
use crate::vm::{Value, VarError};
use alloc::string::{String, ToString};

fn close(a: f64, b: f64, ulps: f64) -> bool {
    if a == b || (a.is_nan() && b.is_nan()) {
        return true;
    }
    (a - b).abs() <= ulps * f64::EPSILON * b.abs().max(f64::MIN_POSITIVE)
}

#[test]
fn fmath_matches_std_within_a_few_ulps() {
    let mut rng = super::differential::Rng::new(42);
    let mut exact = 0u32;
    let mut exact_by = [0u32; 3];
    for _ in 0..20_000 {
        let unit = (rng.next() >> 11) as f64 / (1u64 << 53) as f64; // [0, 1)
        let x = (unit - 0.5) * 200.0;
        let p = unit * 1e6 + 1e-300;
        assert_eq!(fmath::sqrt(p), p.sqrt(), "sqrt({p})");
        assert_eq!(fmath::trunc(x), x.trunc());
        assert_eq!(fmath::round_half_away(x), x.round());
        assert_eq!(fmath::floor(x), x.floor());
        assert!(close(fmath::exp(x), x.exp(), 1.0), "exp({x})");
        assert!(close(fmath::ln(p), p.ln(), 1.0), "ln({p})");
        assert!(close(fmath::log10(p), p.log10(), 1.0), "log10({p})");
        let y = x / 10.0;
        assert!(
            close(fmath::pow(p, y).unwrap(), p.powf(y), 1.0),
            "pow({p}, {y})"
        );
        exact_by[0] += (fmath::exp(x) == x.exp()) as u32;
        exact_by[1] += (fmath::ln(p) == p.ln()) as u32;
        exact_by[2] += (fmath::pow(p, y) == Some(p.powf(y))) as u32;
        exact += (fmath::exp(x) == x.exp()) as u32
            + (fmath::ln(p) == p.ln()) as u32
            + (fmath::pow(p, y) == Some(p.powf(y))) as u32;
        assert!((fmath::sin(x) - x.sin()).abs() < 1e-15, "sin({x})");
        assert!((fmath::cos(x) - x.cos()).abs() < 1e-15, "cos({x})");
        assert!(close(fmath::atan(x), x.atan(), 4.0), "atan({x})");
        let y = (unit * 7.0).fract() * 2.0 - 1.0;
        assert!(
            (fmath::atan2(y * x, x) - (y * x).atan2(x)).abs() < 1e-15,
            "atan2({}, {x})",
            y * x
        );
        assert!(
            (fmath::atan2(x, y) - x.atan2(y)).abs() < 4e-16 * x.atan2(y).abs().max(1.0),
            "atan2({x}, {y})"
        );
        let u = unit * 2.0 - 1.0;
        assert!((fmath::asin(u) - u.asin()).abs() < 1e-15, "asin({u})");
        assert!((fmath::acos(u) - u.acos()).abs() < 1e-15, "acos({u})");
        let t = x / 100.0;
        assert!(close(fmath::tan(t), t.tan(), 8.0), "tan({t})");
    }
    // exp/ln/pow are computed in double-double (error about 0.505 ulp): they differ from
    // std (glibc, itself not always correctly rounded) only for values within a few
    // thousandths of an ulp of a rounding midpoint.
    assert!(
        exact >= 59_700,
        "only {exact} of 60000 results equal to std's ({exact_by:?})"
    );
    for x in [0.0, 1.0, 2.0, 0.25, 1e-310, 4.9e-324, f64::MAX, 1e300] {
        assert_eq!(fmath::sqrt(x), x.sqrt(), "sqrt({x})");
    }
    assert_eq!(fmath::log10(1000.0), 3.0);
    assert_eq!(fmath::log10(0.01), -2.0);
    assert_eq!(fmath::exp(0.0), 1.0);
    assert_eq!(fmath::ln(1.0), 0.0);
    assert_eq!(fmath::pow(2.0, 10.0), Some(1024.0));
    assert_eq!(fmath::pow(-2.0, 3.0), Some(-8.0));
    assert_eq!(fmath::pow(0.0, -1.0), None);
    assert_eq!(fmath::pow(-2.0, 0.5), None);
    assert!(close(
        fmath::pow(2.0, 0.5).unwrap(),
        core::f64::consts::SQRT_2,
        4.0
    ));
    assert_eq!(fmath::round_half_away(2.5), 3.0);
    assert_eq!(fmath::round_half_away(-2.5), -3.0);
    assert_eq!(fmath::round_half_away(0.49999999999999994), 0.0);
}

#[test]
fn math_builtins_through_the_vm() {
    let f64_of = |b: Builtin, x: f64| {
        f64::from_bits(eval(|c| {
            c.push_f64(x);
            c.call_builtin(b);
        }))
    };
    assert_eq!(f64_of(Builtin::SqrtF64, 16.0), 4.0);
    assert_eq!(f64_of(Builtin::AbsF64, -3.5), 3.5);
    assert_eq!(f64_of(Builtin::ExpF64, 0.0), 1.0);
    assert_eq!(f64_of(Builtin::LnF64, 1.0), 0.0);
    assert_eq!(f64_of(Builtin::LogF64, 100.0), 2.0);
    assert_eq!(f64_of(Builtin::SinF64, 0.0), 0.0);
    assert_eq!(f64_of(Builtin::CosF64, 0.0), 1.0);
    assert_eq!(f64_of(Builtin::TanF64, 0.0), 0.0);
    assert_eq!(f64_of(Builtin::AsinF64, 1.0), core::f64::consts::FRAC_PI_2);
    assert_eq!(f64_of(Builtin::AcosF64, 1.0), 0.0);
    assert_eq!(f64_of(Builtin::AtanF64, 0.0), 0.0);
    let expt = f64::from_bits(eval(|c| {
        c.push_f64(3.0);
        c.push_f64(4.0);
        c.call_builtin(Builtin::ExptF64);
    }));
    assert_eq!(expt, 81.0);
    let real = |b: Builtin, x: f32| {
        f32::from_bits(eval(|c| {
            c.push_f32(x);
            c.call_builtin(b);
        }) as u32)
    };
    assert_eq!(real(Builtin::SqrtF32, 2.0), 2f32.sqrt());
    assert_eq!(real(Builtin::AbsF32, -1.25), 1.25);
    assert_eq!(real(Builtin::SinF32, 1.0), 1f32.sin());
    assert_eq!(real(Builtin::CosF32, 1.0), 1f32.cos());
    assert_eq!(real(Builtin::TanF32, 1.0), 1f32.tan());
    assert_eq!(real(Builtin::ExpF32, 1.0), 1f32.exp());
    assert_eq!(real(Builtin::LnF32, 10.0), 10f32.ln());
    assert_eq!(real(Builtin::LogF32, 1000.0), 3.0);
    assert_eq!(real(Builtin::AsinF32, 0.5), 0.5f32.asin());
    assert_eq!(real(Builtin::AcosF32, 0.5), 0.5f32.acos());
    assert_eq!(real(Builtin::AtanF32, 1.0), 1f32.atan());
    let atan2 = |y: f64, x: f64| {
        f64::from_bits(eval(|c| {
            c.push_f64(y);
            c.push_f64(x);
            c.call_builtin(Builtin::Atan2F64);
        }))
    };
    assert_eq!(atan2(1.0, 1.0), core::f64::consts::FRAC_PI_4);
    assert_eq!(atan2(0.0, -1.0), core::f64::consts::PI);
    assert_eq!(atan2(-0.0, -1.0), -core::f64::consts::PI);
    assert_eq!(atan2(-1.0, 0.0), -core::f64::consts::FRAC_PI_2);
    assert_eq!(atan2(0.0, 0.0), 0.0);
    assert_eq!(
        atan2(f64::INFINITY, f64::NEG_INFINITY),
        0.75 * core::f64::consts::PI
    );
    let atan2_real = f32::from_bits(eval(|c| {
        c.push_f32(-1.0);
        c.push_f32(-1.0);
        c.call_builtin(Builtin::Atan2F32);
    }) as u32);
    assert_eq!(atan2_real, (-1f32).atan2(-1.0));
    let expt32 = f32::from_bits(eval(|c| {
        c.push_f32(2.0);
        c.push_f32(-2.0);
        c.call_builtin(Builtin::ExptF32);
    }) as u32);
    assert_eq!(expt32, 0.25);
}

/// Data memory with strings at 0 (cap 10), 20 (cap 10), 40 (cap 4) and 60 (cap 30).
fn strings(a: &str, b: &str) -> Vec<u8> {
    let mut data = vec![0u8; 128];
    for (at, cap, text) in [(0usize, 10u16, a), (20, 10, b), (40, 4, ""), (60, 30, "")] {
        data[at..at + 2].copy_from_slice(&cap.to_le_bytes());
        data[at + 2..at + 4].copy_from_slice(&(text.len() as u16).to_le_bytes());
        data[at + 4..at + 4 + text.len()].copy_from_slice(text.as_bytes());
    }
    data
}

fn text(data: &[u8], at: usize) -> String {
    let len = u16::from_le_bytes([data[at + 2], data[at + 3]]) as usize;
    String::from_utf8(data[at + 4..at + 4 + len].to_vec()).unwrap()
}

/// Runs a string builtin writing to the 30-char string at 60 and returns its text.
fn string_fn(builtin: Builtin, a: &str, b: &str, args: &[u64]) -> String {
    let mut data = strings(a, b);
    let mut all = vec![60u64];
    all.extend_from_slice(args);
    assert_eq!(builtins::call(builtin, &all, &mut data), Ok(None));
    text(&data, 60)
}

#[test]
fn string_functions() {
    use Builtin::*;
    let neg = |v: i64| v as u64;
    assert_eq!(string_fn(StrAssign, "abc", "", &[0]), "abc");
    assert_eq!(string_fn(StrConcat, "abc", "de", &[0, 20]), "abcde");
    assert_eq!(string_fn(StrLeft, "abcdef", "", &[0, 2]), "ab");
    assert_eq!(string_fn(StrLeft, "abcdef", "", &[0, 99]), "abcdef");
    assert_eq!(string_fn(StrLeft, "abcdef", "", &[0, neg(-1)]), "");
    assert_eq!(string_fn(StrRight, "abcdef", "", &[0, 2]), "ef");
    assert_eq!(string_fn(StrMid, "abcdef", "", &[0, 2, 3]), "cd");
    assert_eq!(string_fn(StrMid, "abcdef", "", &[0, 10, 5]), "ef");
    assert_eq!(string_fn(StrMid, "abcdef", "", &[0, 2, 9]), "");
    assert_eq!(
        string_fn(StrInsert, "abcdef", "XY", &[0, 20, 2]),
        "abXYcdef"
    );
    assert_eq!(string_fn(StrInsert, "abc", "XY", &[0, 20, 0]), "XYabc");
    assert_eq!(string_fn(StrDelete, "abcdef", "", &[0, 2, 3]), "abef");
    assert_eq!(
        string_fn(StrReplace, "abcdef", "XYZ", &[0, 20, 2, 3]),
        "abXYZef"
    );
    assert_eq!(string_fn(StrFromI64, "", "", &[neg(-42)]), "-42");
    assert_eq!(
        string_fn(StrFromU64, "", "", &[u64::MAX]),
        "18446744073709551615"
    );
    assert_eq!(
        string_fn(StrFromF32, "", "", &[4.0f32.to_bits() as u64]),
        "4.0"
    );
    assert_eq!(
        string_fn(StrFromF32, "", "", &[0.1f32.to_bits() as u64]),
        "0.1"
    );
    assert_eq!(
        string_fn(StrFromF64, "", "", &[(-2.5f64).to_bits()]),
        "-2.5"
    );
    assert_eq!(string_fn(StrFromBool, "", "", &[1]), "TRUE");
    assert_eq!(string_fn(StrFromBool, "", "", &[0]), "FALSE");
    assert_eq!(
        string_fn(StrFromTime, "", "", &[1_500_000_000]),
        "T#1s500ms"
    );

    let mut data = strings("hello", "lo");
    assert_eq!(builtins::call(StrLen, &[0], &mut data), Ok(Some(5)));
    assert_eq!(builtins::call(StrFind, &[0, 20], &mut data), Ok(Some(4)));
    assert_eq!(builtins::call(StrFind, &[20, 0], &mut data), Ok(Some(0)));
    assert_eq!(
        builtins::call(StrCompare, &[0, 20], &mut data),
        Ok(Some(u64::MAX))
    );
    assert_eq!(builtins::call(StrCompare, &[0, 0], &mut data), Ok(Some(0)));
    // Truncation to the destination's capacity (4), aliasing dst = a.
    assert_eq!(builtins::call(StrConcat, &[40, 0, 20], &mut data), Ok(None));
    assert_eq!(text(&data, 40), "hell");
    assert_eq!(builtins::call(StrConcat, &[0, 0, 20], &mut data), Ok(None));
    assert_eq!(text(&data, 0), "hellolo");
    // Parsing.
    let mut data = strings(" -12_3 ", "2.5e1");
    assert_eq!(
        builtins::call(StrToI64, &[0], &mut data),
        Ok(Some(-123i64 as u64))
    );
    assert_eq!(
        builtins::call(StrToF64, &[20], &mut data),
        Ok(Some(25.0f64.to_bits()))
    );
    let mut data = strings("12x", "");
    assert_eq!(
        builtins::call(StrToI64, &[0], &mut data),
        Err(Trap::NumericError)
    );
    assert_eq!(
        builtins::call(StrToF64, &[20], &mut data),
        Err(Trap::NumericError)
    );
    let mut data = strings("", "");
    let big = b"99999999999999999999";
    data[62..64].copy_from_slice(&(big.len() as u16).to_le_bytes());
    data[64..64 + big.len()].copy_from_slice(big);
    assert_eq!(
        builtins::call(StrToI64, &[60], &mut data),
        Err(Trap::NumericError)
    );
    let min = b"-9223372036854775808";
    data[62..64].copy_from_slice(&(min.len() as u16).to_le_bytes());
    data[64..64 + min.len()].copy_from_slice(min);
    assert_eq!(
        builtins::call(StrToI64, &[60], &mut data),
        Ok(Some(i64::MIN as u64))
    );
    // Invalid string addresses.
    assert_eq!(
        builtins::call(StrLen, &[126], &mut data),
        Err(Trap::InvalidAddress)
    );
    data[100..102].copy_from_slice(&200u16.to_le_bytes());
    assert_eq!(
        builtins::call(StrLen, &[100], &mut data),
        Err(Trap::InvalidAddress)
    );
}

#[test]
fn time_formatting() {
    let fmt = |ns: i64| {
        let mut s = String::new();
        format_time(&mut s, ns);
        s
    };
    assert_eq!(fmt(0), "T#0s");
    assert_eq!(fmt(1_500_000_000), "T#1s500ms");
    assert_eq!(fmt(-2_000_000), "T#-2ms");
    assert_eq!(fmt(90_061_001_001_001), "T#1d1h1m1s1ms1us1ns");
    assert!(fmt(i64::MIN).starts_with("T#-"));
}

/// WSTRINGs at 0 (capacity 12) and 40 (capacity 12), a result WSTRING at 80 (capacity 6),
/// a STRING at 100 (capacity 7).
fn wide_data(a: &str, b: &str, narrow: &[u8]) -> Vec<u8> {
    let mut data = vec![0u8; 120];
    for (at, text) in [(0usize, a), (40, b)] {
        let units: Vec<u16> = text.encode_utf16().collect();
        data[at..at + 2].copy_from_slice(&12u16.to_le_bytes());
        data[at + 2..at + 4].copy_from_slice(&(units.len() as u16).to_le_bytes());
        for (i, u) in units.iter().enumerate() {
            data[at + 4 + 2 * i..at + 6 + 2 * i].copy_from_slice(&u.to_le_bytes());
        }
    }
    data[80..82].copy_from_slice(&6u16.to_le_bytes());
    data[100..102].copy_from_slice(&7u16.to_le_bytes());
    data[102..104].copy_from_slice(&(narrow.len() as u16).to_le_bytes());
    data[104..104 + narrow.len()].copy_from_slice(narrow);
    data
}

fn wide_text(data: &[u8], at: usize) -> String {
    let len = u16::from_le_bytes([data[at + 2], data[at + 3]]) as usize;
    let units: Vec<u16> = (0..len)
        .map(|i| u16::from_le_bytes([data[at + 4 + 2 * i], data[at + 5 + 2 * i]]))
        .collect();
    String::from_utf16_lossy(&units)
}

#[test]
fn wide_strings() {
    use Builtin::*;
    let run = |b: Builtin, x: &str, y: &str, args: &[u64]| {
        let mut data = wide_data(x, y, b"");
        let mut all = vec![80u64];
        all.extend_from_slice(args);
        assert_eq!(builtins::call(b, &all, &mut data), Ok(None), "{b:?}");
        let model = {
            let mut m = wide_data(x, y, b"");
            crate::model::string_builtin(b, &all, &mut m).unwrap();
            m
        };
        assert_eq!(data, model, "{b:?} {x} {y} {args:?}");
        wide_text(&data, 80)
    };
    assert_eq!(run(WStrAssign, "äb€", "", &[0]), "äb€");
    assert_eq!(run(WStrConcat, "äb", "€xyzw", &[0, 40]), "äb€xyz");
    assert_eq!(run(WStrLeft, "äb€", "", &[0, 2]), "äb");
    assert_eq!(run(WStrRight, "äb€", "", &[0, 1]), "€");
    assert_eq!(run(WStrMid, "abcdef", "", &[0, 2, 3]), "cd");
    assert_eq!(run(WStrInsert, "abcd", "€", &[0, 40, 2]), "ab€cd");
    assert_eq!(run(WStrDelete, "abcdef", "", &[0, 2, 2]), "adef");
    assert_eq!(run(WStrReplace, "abcdef", "€", &[0, 40, 3, 2]), "a€ef");
    let mut data = wide_data("ab€c€", "€", b"");
    assert_eq!(builtins::call(WStrFind, &[0, 40], &mut data), Ok(Some(3)));
    assert_eq!(builtins::call(WStrLen, &[0], &mut data), Ok(Some(5)));
    assert_eq!(
        builtins::call(WStrCompare, &[0, 40], &mut data),
        Ok(Some(-1i64 as u64))
    );
    // 'ä' in UTF-8, then a lone Latin-1 byte 0xE9 ('é'), then a 4-byte character (2 units).
    let mut data = wide_data("", "", &[0xC3, 0xA4, 0xE9, 0xF0, 0x9F, 0x98, 0x80]);
    assert_eq!(builtins::call(WStrFromStr, &[80, 100], &mut data), Ok(None));
    assert_eq!(wide_text(&data, 80), "äé😀");
    // Back to UTF-8: the STRING (capacity 7) takes "äé" (4 bytes), the emoji no longer fits.
    assert_eq!(builtins::call(StrFromWStr, &[100, 80], &mut data), Ok(None));
    assert_eq!(text(&data, 100), "äé");
    assert_eq!(
        builtins::call(WStrLen, &[118], &mut data),
        Err(Trap::InvalidAddress)
    );
}

#[test]
fn dates_and_times_of_day() {
    use crate::isa::TimeKind;
    use builtins::{
        NS_PER_DAY, civil_from_days, days_from_civil, format_date_time, parse_date_time,
    };
    let call = |b: Builtin, args: &[u64]| builtins::call(b, args, &mut []);
    // 2024-02-29 is day 19782 after 1970-01-01, a Thursday like 1970-01-01 itself.
    assert_eq!(days_from_civil(2024, 2, 29), 19782);
    assert_eq!(civil_from_days(19782), (2024, 2, 29));
    assert_eq!(civil_from_days(-1), (1969, 12, 31));
    for days in [-200_000i64, -719_468, -1, 0, 59, 10_957, 11_016, 106_751] {
        let (y, m, d) = civil_from_days(days);
        assert_eq!(days_from_civil(y, m, d), days);
    }
    let leap_day = 19782 * NS_PER_DAY as u64;
    assert_eq!(
        call(Builtin::DateFromParts, &[2024, 2, 29]),
        Ok(Some(leap_day))
    );
    for bad in [
        [2023u64, 2, 29],
        [2024, 13, 1],
        [2024, 4, 31],
        [2024, 0, 1],
        [3000, 1, 1],
    ] {
        assert_eq!(
            call(Builtin::DateFromParts, &bad),
            Err(Trap::NumericError),
            "{bad:?}"
        );
    }
    assert_eq!(
        call(Builtin::DateSplit, &[leap_day + 5]),
        Ok(Some(2024 << 16 | 2 << 8 | 29))
    );
    let before_1970 = call(Builtin::DateSplit, &[(-NS_PER_DAY) as u64])
        .unwrap()
        .unwrap();
    assert_eq!(
        ((before_1970 as i64) >> 16, before_1970 & 0xffff),
        (1969, 12 << 8 | 31)
    );
    assert_eq!(call(Builtin::DayOfWeek, &[leap_day]), Ok(Some(4)));
    assert_eq!(
        call(Builtin::DayOfWeek, &[leap_day + 3 * NS_PER_DAY as u64]),
        Ok(Some(0))
    );
    let noon = 12 * 3_600_000_000_000u64;
    assert_eq!(
        call(Builtin::DateOf, &[leap_day + noon]),
        Ok(Some(leap_day))
    );
    assert_eq!(call(Builtin::TodOf, &[leap_day + noon]), Ok(Some(noon)));
    assert_eq!(
        call(Builtin::TodOf, &[(-1i64) as u64]),
        Ok(Some(NS_PER_DAY as u64 - 1))
    );
    assert_eq!(
        call(Builtin::DateOf, &[i64::MIN as u64]),
        Err(Trap::NumericError)
    );
    assert_eq!(call(Builtin::TodFromParts, &[12, 0, 0, 0]), Ok(Some(noon)));
    assert_eq!(
        call(Builtin::TodFromParts, &[24, 0, 0, 0]),
        Err(Trap::NumericError)
    );
    assert_eq!(
        call(Builtin::TodFromParts, &[1, 2, 3, 1000]),
        Err(Trap::NumericError)
    );
    let fmt = |kind, ns: i64| {
        let mut s = String::new();
        format_date_time(&mut s, kind, ns);
        s
    };
    let dt = leap_day as i64 + 13 * 3_600_000_000_000 + 5 * 60_000_000_000 + 250_000_000;
    assert_eq!(fmt(TimeKind::Dt, dt), "DT#2024-02-29-13:05:00.25");
    assert_eq!(fmt(TimeKind::LDt, dt), "LDT#2024-02-29-13:05:00.25");
    assert_eq!(fmt(TimeKind::Date, leap_day as i64), "D#2024-02-29");
    assert_eq!(
        fmt(TimeKind::Tod, noon as i64 + 7),
        "TOD#12:00:00.000000007"
    );
    assert_eq!(fmt(TimeKind::LTime, 1_500_000_000), "LT#1s500ms");
    assert_eq!(fmt(TimeKind::Date, -NS_PER_DAY), "D#1969-12-31");
    for (text, kind, value) in [
        ("DT#2024-02-29-13:05:00.25", TimeKind::Dt, Some(dt)),
        (
            "date_and_time#2024-02-29-13:05:00.25",
            TimeKind::LDt,
            Some(dt),
        ),
        (" 2024-02-29 ", TimeKind::Date, Some(leap_day as i64)),
        ("ld#2024-02-29", TimeKind::Date, Some(leap_day as i64)),
        ("2023-02-29", TimeKind::Date, None),
        ("TOD#12:00", TimeKind::Tod, Some(noon as i64)),
        ("12:00:00.0000000071", TimeKind::LTod, Some(noon as i64 + 7)),
        ("24:00", TimeKind::Tod, None),
        ("12:60", TimeKind::Tod, None),
        ("T#1s500ms", TimeKind::Time, Some(1_500_000_000)),
        ("-1.5S", TimeKind::Time, Some(-1_500_000_000)),
        ("1d_2h", TimeKind::LTime, Some(93_600_000_000_000)),
        ("0.5ns", TimeKind::Time, Some(1)),
        ("T#", TimeKind::Time, None),
        ("1x", TimeKind::Time, None),
        ("D#2024-02-29", TimeKind::Tod, None),
    ] {
        assert_eq!(
            parse_date_time(text.as_bytes(), kind),
            value,
            "{text} as {kind}"
        );
    }
}

#[test]
fn monitor_reads_and_forces_variables_by_name() {
    let mut b = ImageBuilder::new();
    b.reserve_data(128);
    let main = b.declare_pou("Main", 0, 0, 64);
    b.add_task(&TaskDef {
        name: "T".into(),
        kind: TaskKind::Cyclic,
        priority: 0,
        pou: main,
        instance_base: 0,
        interval_ns: 1,
        watchdog_budget: 0,
    });
    b.set_init(0, &(-5i16).to_le_bytes());
    b.init_string(40, 8, "hi");
    b.add_var("Main.i", VarType::Int, 0, 0, 2);
    b.add_var("Main.b", VarType::Bool, 0, 2, 1);
    b.add_var("Main.r", VarType::Real, 0, 4, 4);
    b.add_var("Main.l", VarType::LReal, 0, 8, 8);
    b.add_var("Main.t", VarType::Time, 0, 16, 8);
    b.add_var("Main.w", VarType::Word, 0, 24, 2);
    b.add_var("Main.s", VarType::String, 0, 40, 12);
    b.add_var("K", VarType::DInt, crate::image::VAR_FLAG_CONSTANT, 28, 4);
    b.begin_pou(main);
    // i := i + 1
    b.ld_rel(MemType::I16, 0);
    b.push_i32(1);
    b.op(crate::isa::Opcode::Add);
    b.st_rel(MemType::I16, 0);
    b.ret();
    b.end_pou(main);
    let bytes = b.build().unwrap();
    let image = Image::parse(&bytes).unwrap();
    let verified = verify(&image).unwrap();
    let mut data = [0u8; 128];
    let mut stack = [0u64; 4];
    let mut calls = [CallFrame::EMPTY; 1];
    let mut vm = Machine::new(
        verified,
        Memory {
            data: &mut data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut [],
        },
    )
    .unwrap();
    assert_eq!(vm.read_var("Main.i"), Ok(Value::Int(-5)));
    vm.run_cycle(0, 0).unwrap();
    assert_eq!(vm.read_var("Main.i"), Ok(Value::Int(-4)));
    assert_eq!(vm.read_var("Main.s"), Ok(Value::String(b"hi")));
    vm.write_var("Main.i", Value::Int(70000)).unwrap(); // truncated to INT
    assert_eq!(
        vm.read_var("Main.i"),
        Ok(Value::Int(70000i64 as i16 as i64))
    );
    vm.write_var("Main.b", Value::Bool(true)).unwrap();
    assert_eq!(vm.read_var("Main.b"), Ok(Value::Bool(true)));
    vm.write_var("Main.r", Value::Real(1.5)).unwrap();
    assert_eq!(vm.read_var("Main.r"), Ok(Value::Real(1.5)));
    vm.write_var("Main.l", Value::LReal(-0.25)).unwrap();
    assert_eq!(vm.read_var("Main.l"), Ok(Value::LReal(-0.25)));
    vm.write_var("Main.t", Value::Time(1_000)).unwrap();
    assert_eq!(vm.read_var("Main.t"), Ok(Value::Time(1_000)));
    vm.write_var("Main.w", Value::UInt(0x1_2345)).unwrap();
    assert_eq!(vm.read_var("Main.w"), Ok(Value::UInt(0x2345)));
    vm.write_var("Main.s", Value::String(b"a longer text"))
        .unwrap();
    assert_eq!(vm.read_var("Main.s"), Ok(Value::String(b"a longer")));
    assert_eq!(
        vm.write_var("Main.b", Value::Int(1)),
        Err(VarError::TypeMismatch)
    );
    assert_eq!(vm.write_var("K", Value::Int(1)), Err(VarError::Constant));
    assert_eq!(vm.read_var("nope"), Err(VarError::UnknownName));
    // By map entry, looked up once: the same rules as by name; an entry outside this
    // machine's data (another image's) is refused, not trusted.
    let b_entry = image.var(image.find_var_index("Main.b").unwrap()).unwrap();
    vm.write_entry(&b_entry, Value::Bool(false)).unwrap();
    assert_eq!(vm.read_entry(&b_entry), Value::Bool(false));
    let foreign = crate::image::Var {
        addr: 4096,
        ..b_entry
    };
    assert_eq!(
        vm.write_entry(&foreign, Value::Bool(true)),
        Err(VarError::UnknownName)
    );
    // Verified once, kept: the owned image runs without verifying again; a corrupt one is
    // refused when kept.
    let kept = crate::verify::VerifiedBytes::new(bytes.clone()).unwrap();
    assert!(kept.image().image().same_program(&image));
    let mut corrupt = bytes.clone();
    corrupt.truncate(8);
    assert!(crate::verify::VerifiedBytes::new(corrupt).is_err());
    // Cold restart restores initial values.
    vm.reset();
    assert_eq!(vm.read_var("Main.i"), Ok(Value::Int(-5)));
    // Forcing: the program increments i every cycle, the force holds it.
    vm.force_var("Main.i", Value::Int(100)).unwrap();
    assert_eq!(vm.read_var("Main.i"), Ok(Value::Int(100)));
    vm.run_cycle(0, 0).unwrap();
    vm.run_cycle(0, 0).unwrap();
    assert_eq!(vm.read_var("Main.i"), Ok(Value::Int(100)));
    vm.force_var("Main.i", Value::Int(7)).unwrap(); // re-force replaces the value
    vm.run_cycle(0, 0).unwrap();
    assert_eq!(vm.read_var("Main.i"), Ok(Value::Int(7)));
    vm.unforce_var("Main.i").unwrap();
    vm.run_cycle(0, 0).unwrap();
    assert_eq!(
        vm.read_var("Main.i"),
        Ok(Value::Int(8)),
        "runs freely again"
    );
    assert_eq!(
        vm.force_var("Main.s", Value::String(b"x")),
        Err(VarError::NotForceable)
    );
    assert_eq!(vm.force_var("K", Value::Int(1)), Err(VarError::Constant));
    assert_eq!(
        vm.force_var("Main.b", Value::Int(1)),
        Err(VarError::TypeMismatch)
    );
    vm.clear_forces();
}

/// The date/time types, CHAR, WCHAR, WSTRING and references through the monitor API:
/// each read as its own kind, written and forced only with a value of its type (or one IEC
/// widens to it), a reference never written.
#[test]
fn monitor_of_dates_characters_wide_strings_and_references() {
    use crate::builtins::{NS_PER_DAY, date_from_parts};
    use crate::isa::TimeKind;
    let mut b = ImageBuilder::new();
    b.reserve_data(160);
    let main = b.declare_pou("Main", 0, 0, 0);
    b.add_task(&TaskDef {
        name: "T".into(),
        kind: TaskKind::Cyclic,
        priority: 0,
        pou: main,
        instance_base: 0,
        interval_ns: 1,
        watchdog_budget: 0,
    });
    let date = date_from_parts(2024, 6, 15).unwrap();
    let tod = (12 * 3600 + 30 * 60) * 1_000_000_000i64;
    b.set_init(0, &date.to_le_bytes());
    b.set_init(8, &tod.to_le_bytes());
    b.set_init(16, &(date + tod).to_le_bytes());
    b.set_init(24, &1_500_000i64.to_le_bytes());
    b.set_init(32, b"a");
    b.set_init(34, &0x20acu16.to_le_bytes());
    // WSTRING[4] "Zoë" at 40 (4 + 2 * 4 bytes).
    let mut wide = alloc::vec![4u8, 0, 3, 0];
    wide.extend("Zoë".encode_utf16().flat_map(u16::to_le_bytes));
    wide.resize(12, 0);
    b.set_init(40, &wide);
    // References: to `Main.tod` (object 0 is its 8 bytes), to the middle of it, NULL.
    let object = b.add_object(8, 8, None);
    let cell = |address: u64| address | ((object as u64 + 1) << 32);
    b.set_init(56, &cell(8).to_le_bytes());
    b.set_init(64, &cell(12).to_le_bytes());
    b.add_var("Main.date", VarType::Date, 0, 0, 8);
    b.add_var("Main.tod", VarType::Tod, 0, 8, 8);
    b.add_var("Main.dt", VarType::Dt, 0, 16, 8);
    b.add_var("Main.lt", VarType::LTime, 0, 24, 8);
    b.add_var("Main.c", VarType::Char, 0, 32, 1);
    b.add_var("Main.wc", VarType::WChar, 0, 34, 2);
    b.add_var("Main.ws", VarType::WString, 0, 40, 12);
    b.add_var("Main.p", VarType::Ref, 0, 56, 8);
    b.add_var("Main.q", VarType::Ref, 0, 64, 8);
    b.add_var("Main.n", VarType::Ref, 0, 72, 8);
    b.add_var("Main.ld", VarType::LDate, 0, 80, 8);
    b.begin_pou(main);
    b.ret();
    b.end_pou(main);
    let bytes = b.build().unwrap();
    let image = Image::parse(&bytes).unwrap();
    let mut data = [0u8; 160];
    let mut stack = [0u64; 4];
    let mut calls = [CallFrame::EMPTY; 1];
    let mut vm = Machine::new(
        verify(&image).unwrap(),
        Memory {
            data: &mut data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut [],
        },
    )
    .unwrap();
    let shown = |vm: &Machine, name: &str| vm.read_var(name).unwrap().to_string();
    assert_eq!(shown(&vm, "Main.date"), "D#2024-06-15");
    assert_eq!(shown(&vm, "Main.tod"), "TOD#12:30:00");
    assert_eq!(shown(&vm, "Main.dt"), "DT#2024-06-15-12:30:00");
    assert_eq!(shown(&vm, "Main.lt"), "LT#1ms500us");
    assert_eq!(shown(&vm, "Main.c"), "'a'");
    assert_eq!(shown(&vm, "Main.wc"), "\"€\"");
    assert_eq!(shown(&vm, "Main.ws"), "\"Zoë\"");
    assert_eq!(shown(&vm, "Main.p"), "REF(Main.tod)");
    assert_eq!(shown(&vm, "Main.q"), "16#0000000C");
    assert_eq!(shown(&vm, "Main.n"), "NULL");

    // Writes and forces of their own kinds, and of the kinds IEC widens.
    vm.write_var("Main.tod", Value::Temporal(TimeKind::Tod, 1))
        .unwrap();
    assert_eq!(shown(&vm, "Main.tod"), "TOD#00:00:00.000000001");
    vm.write_var("Main.lt", Value::Time(2_000)).unwrap();
    assert_eq!(
        vm.read_var("Main.lt"),
        Ok(Value::Temporal(TimeKind::LTime, 2_000))
    );
    vm.force_var("Main.ld", Value::Temporal(TimeKind::Date, -NS_PER_DAY))
        .unwrap();
    assert_eq!(shown(&vm, "Main.ld"), "LD#1969-12-31");
    vm.force_var("Main.c", Value::Char(b'z')).unwrap();
    vm.write_var("Main.wc", Value::Char(b'A')).unwrap();
    assert_eq!(
        (shown(&vm, "Main.c"), shown(&vm, "Main.wc")),
        ("'z'".into(), "\"A\"".into())
    );
    let long: Vec<u8> = "Grüße".encode_utf16().flat_map(u16::to_le_bytes).collect();
    vm.write_var("Main.ws", Value::WString(&long)).unwrap();
    assert_eq!(shown(&vm, "Main.ws"), "\"Grüß\"", "cut to its capacity");
    // Forces follow a download by their bytes: a date/time keeps its kind.
    vm.force_bytes("Main.dt", &7i64.to_le_bytes()).unwrap();
    assert_eq!(vm.read_var("Main.dt"), Ok(Value::Temporal(TimeKind::Dt, 7)));

    // What does not fit.
    for (name, value, error) in [
        (
            "Main.date",
            Value::Temporal(TimeKind::Date, 1),
            VarError::TypeMismatch,
        ),
        (
            "Main.date",
            Value::Temporal(TimeKind::Dt, 0),
            VarError::TypeMismatch,
        ),
        ("Main.date", Value::Int(0), VarError::TypeMismatch),
        (
            "Main.tod",
            Value::Temporal(TimeKind::Tod, NS_PER_DAY),
            VarError::TypeMismatch,
        ),
        (
            "Main.tod",
            Value::Temporal(TimeKind::LTod, 0),
            VarError::TypeMismatch,
        ),
        ("Main.lt", Value::Int(5), VarError::TypeMismatch),
        ("Main.c", Value::WChar(65), VarError::TypeMismatch),
        ("Main.c", Value::UInt(65), VarError::TypeMismatch),
        ("Main.ws", Value::String(b"x"), VarError::TypeMismatch),
        ("Main.ws", Value::WString(b"odd"), VarError::TypeMismatch),
        ("Main.p", Value::UInt(8), VarError::ReadOnly),
        (
            "Main.n",
            Value::Ref {
                address: Some(8),
                target: None,
            },
            VarError::ReadOnly,
        ),
    ] {
        assert_eq!(
            vm.write_var(name, value),
            Err(error),
            "write {name} {value:?}"
        );
        let force_error = match name {
            "Main.ws" => VarError::NotForceable,
            _ => error,
        };
        assert_eq!(
            vm.force_var(name, value),
            Err(force_error),
            "force {name} {value:?}"
        );
    }
    assert_eq!(vm.force_bytes("Main.p", &[0; 8]), Err(VarError::ReadOnly));
    assert_eq!(shown(&vm, "Main.p"), "REF(Main.tod)", "unchanged");
}

#[test]
fn force_table_capacity() {
    let mut b = ImageBuilder::new();
    b.reserve_data(256);
    let main = b.declare_pou("Main", 0, 0, 0);
    b.add_task(&TaskDef {
        name: "T".into(),
        kind: TaskKind::Cyclic,
        priority: 0,
        pou: main,
        instance_base: 0,
        interval_ns: 1,
        watchdog_budget: 0,
    });
    let count = crate::vm::MAX_FORCES + 1;
    let names: Vec<String> = (0..count).map(|i| alloc::format!("v{i}")).collect();
    for (i, name) in names.iter().enumerate() {
        b.add_var(name, VarType::DInt, 0, 4 * i as u32, 4);
    }
    b.begin_pou(main);
    b.ret();
    b.end_pou(main);
    let bytes = b.build().unwrap();
    let image = Image::parse(&bytes).unwrap();
    let mut data = [0u8; 256];
    let mut stack = [0u64; 4];
    let mut calls = [CallFrame::EMPTY; 1];
    let mut vm = Machine::new(
        verify(&image).unwrap(),
        Memory {
            data: &mut data,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut [],
        },
    )
    .unwrap();
    for name in &names[..count - 1] {
        vm.force_var(name, Value::Int(1)).unwrap();
    }
    assert_eq!(
        vm.force_var(&names[count - 1], Value::Int(1)),
        Err(VarError::TooManyForces)
    );
    vm.unforce_var(&names[0]).unwrap();
    assert_eq!(vm.force_var(&names[count - 1], Value::Int(1)), Ok(()));
}

#[test]
fn machine_setup_errors() {
    let bytes = program_with(10, |c, _| c.nop());
    let image = Image::parse(&bytes).unwrap();
    let verified = verify(&image).unwrap();
    let mut small = [0u8; 8];
    let mut stack = [0u64; 4];
    let mut calls = [CallFrame::EMPTY; 1];
    let err = Machine::new(
        verified,
        Memory {
            data: &mut small,
            stack: &mut stack,
            calls: &mut calls,
            tries: &mut [],
        },
    )
    .err();
    assert_eq!(
        err,
        Some(crate::vm::SetupError::DataTooSmall {
            needed: DATA,
            given: 8
        })
    );
    let mut data = [0u8; DATA as usize];
    let err = Machine::new(
        verified,
        Memory {
            data: &mut data,
            stack: &mut [],
            calls: &mut calls,
            tries: &mut [],
        },
    )
    .err();
    assert_eq!(err, Some(crate::vm::SetupError::NoStackOrFrames));
}
