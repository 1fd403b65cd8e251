//! Floating-point math without `std` (core has no `sqrt`, `sin`, ...): deterministic,
//! bit-for-bit identical on every platform because it only uses IEEE-754 basic operations.
//!
//! `sqrt`, `trunc` and the rounding functions are exact (correctly rounded). `exp`, `ln`,
//! `log10` and `pow` are computed in double-double arithmetic (error about 0.505 ulp, so almost
//! always the correctly rounded value, and exact whenever the result is representable, e.g.
//! `pow(2, 10)`, `pow(4, 0.5)`, `log10(1000)`). The trigonometric functions follow the classic
//! fdlibm polynomial kernels (< 1 ulp) with a three-part Cody–Waite argument reduction that is
//! accurate for |x| up to about 1e6 (beyond that precision degrades).

// The polynomial coefficients are fdlibm's published decimal values, kept verbatim so they
// can be checked against the source; their extra digits are harmless.
#![allow(clippy::excessive_precision)]

use crate::isa::{MemType, RoundMode};

const TWO52: f64 = 4503599627370496.0;

/// Rounds toward zero.
pub fn trunc(x: f64) -> f64 {
    let bits = x.to_bits();
    let exponent = ((bits >> 52) & 0x7ff) as i32 - 1023;
    if exponent >= 52 {
        return x; // already integral (or NaN/inf)
    }
    if exponent < 0 {
        return f64::from_bits(bits & (1 << 63)); // |x| < 1: signed zero
    }
    let fraction_mask = (1u64 << (52 - exponent)) - 1;
    f64::from_bits(bits & !fraction_mask)
}

/// Rounds to nearest, ties away from zero.
pub fn round_half_away(x: f64) -> f64 {
    if x.is_nan() || x.abs() >= TWO52 {
        return x;
    }
    let t = trunc(x);
    // x - t is exact for |x| < 2^52.
    let diff = x - t;
    if diff >= 0.5 {
        t + 1.0
    } else if diff <= -0.5 {
        t - 1.0
    } else {
        t
    }
}

/// Rounds toward negative infinity.
pub fn floor(x: f64) -> f64 {
    let t = trunc(x);
    if t > x { t - 1.0 } else { t }
}

/// Integer square root of a u128 (largest r with r*r <= n).
fn isqrt(n: u128) -> u128 {
    let mut result = 0u128;
    let mut bit = 1u128 << 126;
    let mut rest = n;
    while bit > rest {
        bit >>= 2;
    }
    while bit != 0 {
        if rest >= result + bit {
            rest -= result + bit;
            result = (result >> 1) + bit;
        } else {
            result >>= 1;
        }
        bit >>= 2;
    }
    result
}

/// Correctly rounded square root (NaN for negative input).
pub fn sqrt(x: f64) -> f64 {
    if x.is_nan() || x < 0.0 {
        return f64::NAN;
    }
    if x == 0.0 || x.is_infinite() {
        return x;
    }
    let bits = x.to_bits();
    let mut exponent = ((bits >> 52) & 0x7ff) as i64;
    let mut mantissa = bits & ((1 << 52) - 1);
    if exponent == 0 {
        let shift = mantissa.leading_zeros() as i64 - 11;
        mantissa <<= shift;
        exponent = 1 - shift;
    } else {
        mantissa |= 1 << 52;
    }
    // x = mantissa * 2^e with mantissa in [2^52, 2^53).
    let mut e = exponent - 1075;
    let mut m = mantissa as u128;
    if e & 1 != 0 {
        m <<= 1;
        e -= 1;
    }
    let n = m << 54;
    let root = isqrt(n); // in [2^53, 2^54)
    let exact = root * root == n;
    let dropped = root & 1;
    let mut r = root >> 1;
    if dropped == 1 && (!exact || r & 1 == 1) {
        r += 1;
    }
    // sqrt(x) = r * 2^(e/2 - 26), r in [2^52, 2^53].
    let mut e_res = e / 2 - 26;
    if r == 1 << 53 {
        r >>= 1;
        e_res += 1;
    }
    let biased = (e_res + 52 + 1023) as u64;
    f64::from_bits((biased << 52) | (r as u64 & ((1 << 52) - 1)))
}

/// x * 2^n.
fn scalbn(mut x: f64, mut n: i32) -> f64 {
    let two1023 = f64::from_bits(0x7fe0_0000_0000_0000);
    let two_m1022 = f64::from_bits(0x0010_0000_0000_0000);
    while n > 1023 {
        x *= two1023;
        n -= 1023;
        if x.is_infinite() {
            return x;
        }
    }
    while n < -1022 {
        x *= two_m1022 * TWO52; // 2^-970, keeps precision for subnormal results
        n += 970;
        if x == 0.0 {
            return x;
        }
    }
    x * f64::from_bits(((n + 1023) as u64) << 52)
}

const LN2_HI: f64 = 6.931_471_803_691_238_164_90e-01;
const LN2_LO: f64 = 1.908_214_929_270_587_700_02e-10;

/// e^x, nearly correctly rounded (see `exp_dd`).
pub fn exp(x: f64) -> f64 {
    exp_dd(x, 0.0)
}

/// Natural logarithm (NaN for x < 0, -inf for 0), nearly correctly rounded.
pub fn ln(x: f64) -> f64 {
    if x.is_nan() || x < 0.0 {
        return f64::NAN;
    }
    if x == 0.0 {
        return f64::NEG_INFINITY;
    }
    if x.is_infinite() {
        return x;
    }
    let (hi, lo) = ln_dd(x);
    hi + lo
}

/// Base-10 logarithm, nearly correctly rounded (exact for exact powers of ten).
pub fn log10(x: f64) -> f64 {
    if x.is_nan() || x <= 0.0 || x.is_infinite() {
        return ln(x);
    }
    const LOG10_E_LO: f64 = 1.098_319_650_216_765e-17;
    let (hi, lo) = ln_dd(x);
    let (p, e) = two_prod(hi, core::f64::consts::LOG10_E);
    p + (e + hi * LOG10_E_LO + lo * core::f64::consts::LOG10_E)
}

fn sin_kernel(x: f64) -> f64 {
    const S1: f64 = -1.666_666_666_666_663_243_48e-01;
    const S2: f64 = 8.333_333_333_322_489_461_24e-03;
    const S3: f64 = -1.984_126_982_985_794_931_34e-04;
    const S4: f64 = 2.755_731_370_707_006_767_89e-06;
    const S5: f64 = -2.505_076_025_340_686_341_95e-08;
    const S6: f64 = 1.589_690_995_211_550_102_21e-10;
    let z = x * x;
    let r = S2 + z * (S3 + z * (S4 + z * (S5 + z * S6)));
    x + z * x * (S1 + z * r)
}

fn cos_kernel(x: f64) -> f64 {
    const C1: f64 = 4.166_666_666_666_660_190_37e-02;
    const C2: f64 = -1.388_888_888_887_410_957_49e-03;
    const C3: f64 = 2.480_158_728_947_672_941_78e-05;
    const C4: f64 = -2.755_731_435_139_066_330_35e-07;
    const C5: f64 = 2.087_572_321_298_174_827_90e-09;
    const C6: f64 = -1.135_964_755_778_819_482_65e-11;
    let z = x * x;
    let r = z * (C1 + z * (C2 + z * (C3 + z * (C4 + z * (C5 + z * C6)))));
    let hz = 0.5 * z;
    let w = 1.0 - hz;
    w + (((1.0 - w) - hz) + z * r)
}

/// Reduces x to y in [-pi/4, pi/4] with x = n*pi/2 + y; returns (n mod 4, y).
fn reduce(x: f64) -> (i64, f64) {
    const PIO2_1: f64 = 1.570_796_326_734_125_614_17e+00;
    const PIO2_2: f64 = 6.077_100_506_303_965_976_60e-11;
    const PIO2_3: f64 = 2.022_266_248_711_166_455_80e-21;
    if x.abs() <= core::f64::consts::FRAC_PI_4 {
        return (0, x);
    }
    let n = round_half_away(x * core::f64::consts::FRAC_2_PI);
    let y = ((x - n * PIO2_1) - n * PIO2_2) - n * PIO2_3;
    let quadrant = (n % 4.0) as i64;
    (quadrant.rem_euclid(4), y)
}

/// Sine (radians).
pub fn sin(x: f64) -> f64 {
    if !x.is_finite() {
        return f64::NAN;
    }
    let (n, y) = reduce(x);
    match n {
        0 => sin_kernel(y),
        1 => cos_kernel(y),
        2 => -sin_kernel(y),
        _ => -cos_kernel(y),
    }
}

/// Cosine (radians).
pub fn cos(x: f64) -> f64 {
    if !x.is_finite() {
        return f64::NAN;
    }
    let (n, y) = reduce(x);
    match n {
        0 => cos_kernel(y),
        1 => -sin_kernel(y),
        2 => -cos_kernel(y),
        _ => sin_kernel(y),
    }
}

/// Tangent (radians).
pub fn tan(x: f64) -> f64 {
    if !x.is_finite() {
        return f64::NAN;
    }
    let (n, y) = reduce(x);
    let (s, c) = (sin_kernel(y), cos_kernel(y));
    if n % 2 == 0 { s / c } else { -c / s }
}

/// Arc tangent.
pub fn atan(x: f64) -> f64 {
    const ATAN_HI: [f64; 4] = [
        4.636_476_090_008_060_935_15e-01,
        core::f64::consts::FRAC_PI_4,
        9.827_937_232_473_290_540_82e-01,
        core::f64::consts::FRAC_PI_2,
    ];
    const ATAN_LO: [f64; 4] = [
        2.269_877_745_296_168_709_24e-17,
        3.061_616_997_868_383_017_93e-17,
        1.390_331_103_123_099_845_16e-17,
        6.123_233_995_736_766_035_87e-17,
    ];
    const AT: [f64; 11] = [
        3.333_333_333_333_293_180_27e-01,
        -1.999_999_999_987_648_324_76e-01,
        1.428_571_427_250_346_637_11e-01,
        -1.111_111_040_546_235_578_80e-01,
        9.090_887_133_436_506_561_96e-02,
        -7.691_876_205_044_829_994_95e-02,
        6.661_073_137_387_531_206_69e-02,
        -5.833_570_133_790_573_486_45e-02,
        4.976_877_994_615_932_360_17e-02,
        -3.653_157_274_421_691_552_70e-02,
        1.628_582_011_536_578_236_23e-02,
    ];
    if x.is_nan() {
        return x;
    }
    let negative = x < 0.0;
    let mut ax = x.abs();
    if ax >= 7.378_697_629_483_821e19 {
        let r = ATAN_HI[3] + ATAN_LO[3];
        return if negative { -r } else { r };
    }
    let id: i32;
    if ax < 0.4375 {
        id = -1;
    } else if ax < 1.1875 {
        if ax < 0.6875 {
            id = 0;
            ax = (2.0 * ax - 1.0) / (2.0 + ax);
        } else {
            id = 1;
            ax = (ax - 1.0) / (ax + 1.0);
        }
    } else if ax < 2.4375 {
        id = 2;
        ax = (ax - 1.5) / (1.0 + 1.5 * ax);
    } else {
        id = 3;
        ax = -1.0 / ax;
    }
    let z = ax * ax;
    let w = z * z;
    let s1 = z * (AT[0] + w * (AT[2] + w * (AT[4] + w * (AT[6] + w * (AT[8] + w * AT[10])))));
    let s2 = w * (AT[1] + w * (AT[3] + w * (AT[5] + w * (AT[7] + w * AT[9]))));
    let r = if id < 0 {
        ax - ax * (s1 + s2)
    } else {
        let i = id as usize;
        ATAN_HI[i] - ((ax * (s1 + s2) - ATAN_LO[i]) - ax)
    };
    if negative { -r } else { r }
}

/// Angle of the point (x, y) in radians, in [-pi, pi] (IEEE `atan2` for the special values:
/// signed zeros and infinities give the exact quadrant angles, a NaN gives NaN).
pub fn atan2(y: f64, x: f64) -> f64 {
    use core::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};
    // pi = PI + PI_LO exactly enough for pi - z.
    const PI_LO: f64 = 1.224_646_799_147_353_207_2e-16;
    if x.is_nan() || y.is_nan() {
        return f64::NAN;
    }
    let negative_y = y.is_sign_negative();
    let signed = |r: f64| if negative_y { -r } else { r };
    if y == 0.0 {
        // Toward +x the angle is y itself (+0/-0); toward -x it is +-pi.
        return if x.is_sign_negative() { signed(PI) } else { y };
    }
    if x == 0.0 {
        return signed(FRAC_PI_2);
    }
    if x.is_infinite() {
        return match (y.is_infinite(), x > 0.0) {
            (true, true) => signed(FRAC_PI_4),
            (true, false) => signed(3.0 * FRAC_PI_4),
            (false, true) => signed(0.0),
            (false, false) => signed(PI),
        };
    }
    if y.is_infinite() {
        return signed(FRAC_PI_2);
    }
    let z = atan((y / x).abs());
    signed(if x > 0.0 { z } else { PI - (z - PI_LO) })
}

/// Arc sine (NaN outside [-1, 1]).
pub fn asin(x: f64) -> f64 {
    if !(-1.0..=1.0).contains(&x) {
        return f64::NAN;
    }
    if x.abs() == 1.0 {
        return if x > 0.0 {
            core::f64::consts::FRAC_PI_2
        } else {
            -core::f64::consts::FRAC_PI_2
        };
    }
    atan(x / sqrt((1.0 - x) * (1.0 + x)))
}

/// Arc cosine (NaN outside [-1, 1]).
pub fn acos(x: f64) -> f64 {
    if !(-1.0..=1.0).contains(&x) {
        return f64::NAN;
    }
    if x == -1.0 {
        return core::f64::consts::PI;
    }
    2.0 * atan(sqrt((1.0 - x) / (1.0 + x)))
}

// ---- double-double helpers: a value is hi + lo with |lo| <= ulp(hi)/2 ----

/// Exact sum: a + b = s + e.
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

/// Splits a into two 26-bit halves (Dekker).
fn split(a: f64) -> (f64, f64) {
    let t = 134_217_729.0 * a; // 2^27 + 1
    let hi = t - (t - a);
    (hi, a - hi)
}

/// Exact product: a * b = p + e (no FMA in core, so Dekker's algorithm).
fn two_prod(a: f64, b: f64) -> (f64, f64) {
    let p = a * b;
    let (ah, al) = split(a);
    let (bh, bl) = split(b);
    (p, ((ah * bh - p) + ah * bl + al * bh) + al * bl)
}

/// ln(x) for finite x > 0 as a double-double (relative error about 2^-62).
fn ln_dd(x: f64) -> (f64, f64) {
    let mut bits = x.to_bits();
    let mut k: i64 = 0;
    if bits >> 52 == 0 {
        bits = (x * TWO52 * 4.0).to_bits();
        k -= 54;
    }
    k += ((bits >> 52) & 0x7ff) as i64 - 1023;
    let mut m = f64::from_bits((bits & ((1 << 52) - 1)) | (1023 << 52));
    if m > core::f64::consts::SQRT_2 {
        m *= 0.5; // exact
        k += 1;
    }
    // ln(m) = 2 atanh(f), f = (m - 1) / (m + 1), |f| < 0.1716.
    let num = m - 1.0; // exact (Sterbenz)
    let (den_hi, den_lo) = two_sum(m, 1.0);
    let f_hi = num / den_hi;
    // f_lo = (num - f_hi * den) / den, computed with an exact product.
    let (p, e) = two_prod(f_hi, den_hi);
    let f_lo = (((num - p) - e) - f_hi * den_lo) / den_hi;
    // tail = 2 (f^3/3 + f^5/5 + ...) in plain double: it is < 1% of the result.
    let z = f_hi * f_hi;
    let mut series = 0.0;
    let mut n = 29.0;
    while n >= 3.0 {
        series = series * z + 1.0 / n;
        n -= 2.0;
    }
    let tail = 2.0 * f_hi * z * series;
    // 2f + tail
    let (s_hi, s_lo) = two_sum(2.0 * f_hi, tail);
    let s_lo = s_lo + 2.0 * f_lo;
    // + k ln2 (LN2_HI has 32 significant bits: k * LN2_HI is exact)
    let dk = k as f64;
    let (r_hi, r_lo) = two_sum(dk * LN2_HI, s_hi);
    let (klo_hi, klo_lo) = two_prod(dk, LN2_LO);
    let (r_hi, r_lo2) = two_sum(r_hi, klo_hi);
    (r_hi, r_lo + r_lo2 + s_lo + klo_lo + dk * LN2_LO_REST)
}

/// The part of ln 2 beyond LN2_HI + LN2_LO.
const LN2_LO_REST: f64 = 1.1612227229362532e-26;

/// e^(hi + lo) for a double-double argument, nearly correctly rounded (error < 0.55 ulp).
fn exp_dd(hi: f64, lo: f64) -> f64 {
    if hi.is_nan() {
        return hi;
    }
    if hi > 709.782_712_893_384 {
        return f64::INFINITY;
    }
    if hi < -745.133_219_101_941_1 {
        return 0.0;
    }
    let k = round_half_away(hi * core::f64::consts::LOG2_E);
    // r = hi + lo - k ln2 as a double-double.
    let (a, a_err) = two_sum(hi - k * LN2_HI, -k * LN2_LO); // hi - k*LN2_HI is exact
    let r_hi_lo = two_sum(a, lo);
    let r_hi = r_hi_lo.0;
    let r_lo = r_hi_lo.1 + a_err - k * LN2_LO_REST;
    // e^r = 1 + r + r^2/2 + (r^3/3! + ...): the first three terms in double-double, the
    // rest (< 1% of the result) in plain double.
    let mut u = 0.0;
    let mut n = 16.0;
    while n >= 3.0 {
        u = (u + 1.0) * r_hi / n;
        n -= 1.0;
    }
    let (sq_hi, sq_lo) = two_prod(r_hi, r_hi);
    let tail = u * sq_hi * 0.5;
    let (s, e1) = two_sum(1.0, r_hi);
    let (s, e2) = two_sum(s, sq_hi * 0.5);
    let sum = s + (e1 + e2 + r_lo + sq_lo * 0.5 + tail + r_lo * r_hi);
    scalbn(sum, k as i32)
}

/// base^exponent; `None` for 0 to a negative power and a negative base to a non-integer
/// power. Computed as exp(exponent * ln |base|) in double-double precision, so exactly
/// representable results (2^10, 3^4, 4^0.5) are exact and others are nearly correctly rounded.
pub fn pow(base: f64, exponent: f64) -> Option<f64> {
    if base.is_nan() || exponent.is_nan() {
        return Some(f64::NAN);
    }
    if exponent == 0.0 || base == 1.0 {
        return Some(1.0);
    }
    let integral = trunc(exponent) == exponent;
    if base == 0.0 {
        return if exponent < 0.0 { None } else { Some(0.0) };
    }
    if base < 0.0 && !integral {
        return None;
    }
    let magnitude = if base.is_infinite() {
        if exponent > 0.0 { f64::INFINITY } else { 0.0 }
    } else if exponent.is_infinite() {
        let above_one = base.abs() > 1.0;
        if above_one == (exponent > 0.0) {
            f64::INFINITY
        } else {
            0.0
        }
    } else {
        let (l_hi, l_lo) = ln_dd(base.abs());
        let (t_hi, t_lo) = two_prod(exponent, l_hi);
        let t_lo = t_lo + exponent * l_lo;
        let (t_hi, t_lo2) = two_sum(t_hi, t_lo);
        exp_dd(t_hi, t_lo2)
    };
    let odd = integral && trunc(exponent * 0.5) * 2.0 != exponent;
    Some(if base < 0.0 && odd {
        -magnitude
    } else {
        magnitude
    })
}

/// Converts a float to an integer cell of type `target` with rounding `mode`;
/// `None` for NaN, infinities and values outside the target range.
pub fn float_to_int(x: f64, target: MemType, mode: RoundMode) -> Option<u64> {
    if !x.is_finite() {
        return None;
    }
    let r = match mode {
        RoundMode::Truncate => trunc(x),
        RoundMode::NearestTiesAway => round_half_away(x),
    };
    // Exact power-of-two bounds: lo <= r < hi_exclusive.
    let (lo, hi_exclusive): (f64, f64) = match target {
        MemType::I8 => (-128.0, 128.0),
        MemType::I16 => (-32768.0, 32768.0),
        MemType::I32 => (-2147483648.0, 2147483648.0),
        MemType::I64 => (-9223372036854775808.0, 9223372036854775808.0),
        MemType::U8 => (0.0, 256.0),
        MemType::U16 => (0.0, 65536.0),
        MemType::U32 => (0.0, 4294967296.0),
        MemType::U64 => (0.0, 18446744073709551616.0),
        MemType::F32 | MemType::F64 => return None,
    };
    if r < lo || r >= hi_exclusive {
        return None;
    }
    Some(if r < 0.0 { r as i64 as u64 } else { r as u64 })
}
