//! Numbers as a reader sees them: a chosen number of significant digits, no float noise
//! (`3999.9999999999995` prints as `4000`), relative errors as percentages that never collapse to
//! `0.000`. Terminal output, reports and messages all format through these.
//!
//! ```
//! use rfe::display::{relative, sig};
//! assert_eq!(sig(3999.9999999999995, 6), "4000");
//! assert_eq!(sig(0.0097853, 3), "0.00979");
//! assert_eq!(sig(2.5e-7, 3), "2.5e-7");
//! assert_eq!(relative(4.98e-4), "0.050 %");
//! ```

/// `x` rounded to `digits` significant digits (at least 1), trailing zeros dropped: plain
/// notation for 1e-4 ≤ |x| < 1e6, scientific (`2.5e-7`) outside. NaN and infinities print as
/// Rust does (`NaN`, `inf`).
pub fn sig(x: f64, digits: usize) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    if x == 0.0 {
        return "0".into();
    }
    let digits = digits.max(1);
    // Round once in scientific form; the exponent after rounding decides the notation.
    let e = format!("{:.*e}", digits - 1, x);
    let (mantissa, exp) = e.split_once('e').unwrap_or((&e, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    if !(-4..6).contains(&exp) {
        return format!("{}e{exp}", trim(mantissa));
    }
    let decimals = (digits as i32 - 1 - exp).max(0) as usize;
    let rounded: f64 = e.parse().unwrap_or(x);
    trim(&format!("{rounded:.decimals$}"))
}

/// A relative error (a fraction: 0.0005 = 0.05 %) as a percentage with two significant digits.
pub fn relative(r: f64) -> String {
    if !r.is_finite() {
        return "—".into();
    }
    let p = 100.0 * r.abs();
    if p == 0.0 {
        return "0 %".into();
    }
    // Two significant digits, keeping the trailing zero that says so (0.050 %, 1.0 %).
    let exp = p.log10().floor() as i32;
    if !(-4..3).contains(&exp) {
        return format!("{} %", sig(p, 2));
    }
    let decimals = (1 - exp).max(0) as usize;
    format!("{p:.decimals$} %")
}

/// A p-value with two significant digits; below 1e-15 (where `1 − cdf` has lost every digit)
/// it reads `< 1e-15`, never `0`.
pub fn p_value(p: f64) -> String {
    if p.is_finite() && p < 1e-15 {
        "< 1e-15".into()
    } else {
        sig(p, 2)
    }
}

/// Drops trailing zeros after a decimal point, and the point itself.
fn trim(s: &str) -> String {
    if !s.contains('.') {
        return s.to_string();
    }
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// A number for tables: five significant digits between 1e-3 and 1e5, else scientific.
pub fn num(x: f64) -> String {
    if x == 0.0 {
        "0".into()
    } else if x.abs() >= 1e-3 && x.abs() < 1e5 {
        let digits = (4 - x.abs().log10().floor() as i32).max(0) as usize;
        format!("{x:.digits$}")
    } else {
        format!("{x:.4e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn significant_digits_without_float_noise() {
        let cases: &[(f64, usize, &str)] = &[
            (3999.9999999999995, 6, "4000"),
            (4000.0000000000005, 6, "4000"),
            (0.1 + 0.2, 6, "0.3"),
            (1.2024, 5, "1.2024"),
            (2120.3456, 5, "2120.3"),
            (-0.0097853, 3, "-0.00979"),
            (99999.95, 6, "99999.9"),
            (999999.5, 6, "1e6"),
            (9.9999999e-5, 3, "0.0001"),
            (2.5e-7, 3, "2.5e-7"),
            (1.5e12, 4, "1.5e12"),
            (0.0, 4, "0"),
            (12.0, 1, "10"),
        ];
        for &(x, d, want) in cases {
            assert_eq!(sig(x, d), want, "sig({x}, {d})");
        }
        assert_eq!(sig(f64::NAN, 3), "NaN");
        assert_eq!(sig(f64::INFINITY, 3), "inf");
    }

    #[test]
    fn relative_errors_never_read_zero() {
        let cases: &[(f64, &str)] = &[
            (4.98e-4, "0.050 %"),
            (0.0109, "1.1 %"),
            (0.1234, "12 %"),
            (1.5, "150 %"),
            (2e-9, "2e-7 %"),
            (0.0, "0 %"),
        ];
        for &(r, want) in cases {
            assert_eq!(relative(r), want, "relative({r})");
        }
        for r in [1e-6, 3.3e-5, 4.4e-4, 5.5e-3] {
            let s = relative(r);
            assert!(!s.starts_with("0.00 ") && s != "0 %", "{r}: {s}");
        }
    }

    #[test]
    fn p_values_never_read_zero() {
        assert_eq!(p_value(0.0), "< 1e-15");
        assert_eq!(p_value(3.2e-20), "< 1e-15");
        assert_eq!(p_value(4.6e-4), "0.00046");
        assert_eq!(p_value(0.2345), "0.23");
        assert_eq!(p_value(1.0), "1");
    }
}
