//! Numbers for people: four significant digits, no trailing zeros, scientific notation
//! only where a fixed one would hide the value.

use std::fmt;

/// `x` with four significant digits: `0.04167`, `14`, `1250`, `3.142e-5`, `2.5e7`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Significant(pub f64);

impl fmt::Display for Significant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let x = self.0;
        if !x.is_finite() || x == 0.0 {
            return write!(f, "{x}");
        }
        let exponent = x.abs().log10().floor() as i32;
        if !(-4..4).contains(&exponent) {
            let text = format!("{x:.3e}");
            // 3.000e-5 → 3e-5
            return match text.split_once('e') {
                Some((mantissa, power)) => {
                    let mantissa = trim(mantissa);
                    write!(f, "{mantissa}e{power}")
                }
                None => f.write_str(&text),
            };
        }
        let decimals = (3 - exponent).max(0) as usize;
        f.write_str(trim(&format!("{x:.decimals$}")))
    }
}

fn trim(text: &str) -> &str {
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.')
    } else {
        text
    }
}

#[cfg(test)]
mod tests {
    use super::Significant;

    #[test]
    fn four_significant_digits_without_trailing_zeros() {
        let cases = [
            (0.041666666666666664, "0.04167"),
            (14.0, "14"),
            (1250.0, "1250"),
            (-0.5, "-0.5"),
            (3.14159e-5, "3.142e-5"),
            (2.5e7, "2.5e7"),
            (0.0, "0"),
            (123456.0, "1.235e5"),
            (0.97, "0.97"),
        ];
        for (x, expected) in cases {
            assert_eq!(Significant(x).to_string(), expected, "{x}");
        }
    }
}
