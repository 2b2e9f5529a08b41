//! The velocity sets: D3Q7 (rest and the six axis links) and D3Q19 (and the twelve face
//! diagonals), their weights and lattice sound speed c_s² = Σ_i w_i e_ix².

use serde::{Deserialize, Serialize};

/// A velocity set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Velocities {
    /// Rest and the six axis links (Bernabei's blockwise lattice, ch. 4).
    #[default]
    D3q7,
    /// Rest, the six axis links and the twelve face diagonals (Geist et al. 2004).
    D3q19,
}

/// A velocity set's links: e_i, w_i and the opposite of each.
#[derive(Debug, Clone, PartialEq)]
pub struct Links {
    /// Link vectors, e_0 = 0 (the rest population).
    pub e: Vec<[i32; 3]>,
    /// Weights, Σ w_i = 1.
    pub w: Vec<f64>,
    /// ī with e_ī = −e_i (0 for the rest).
    pub opposite: Vec<usize>,
    /// c_s² = Σ_i w_i e_ix² (the same on every axis).
    pub cs2: f64,
}

impl Velocities {
    /// Number of populations per cell.
    pub fn len(self) -> usize {
        match self {
            Velocities::D3q7 => 7,
            Velocities::D3q19 => 19,
        }
    }

    /// Always false: a set has its rest population at least.
    pub fn is_empty(self) -> bool {
        false
    }

    /// The links. D3Q7: w_0 = 1/4, w_axis = 1/8 (c_s² = 1/4, the usual diffusion lattice);
    /// D3Q19: w_0 = 1/3, w_axis = 1/18, w_diagonal = 1/36 (c_s² = 1/3). The odd links
    /// come in pairs (2k − 1, 2k), each the other's opposite.
    pub fn links(self) -> Links {
        let mut e = vec![[0, 0, 0]];
        let mut w = Vec::new();
        let (w0, axis, diagonal) = match self {
            Velocities::D3q7 => (0.25, 0.125, 0.0),
            Velocities::D3q19 => (1.0 / 3.0, 1.0 / 18.0, 1.0 / 36.0),
        };
        w.push(w0);
        for a in 0..3 {
            for s in [1, -1] {
                let mut v = [0; 3];
                v[a] = s;
                e.push(v);
                w.push(axis);
            }
        }
        if self == Velocities::D3q19 {
            for (a, b) in [(0, 1), (0, 2), (1, 2)] {
                for (sa, sb) in [(1, 1), (-1, -1), (1, -1), (-1, 1)] {
                    let mut v = [0; 3];
                    v[a] = sa;
                    v[b] = sb;
                    e.push(v);
                    w.push(diagonal);
                }
            }
        }
        let opposite = e
            .iter()
            .map(|v| {
                e.iter()
                    .position(|u| u.iter().zip(v).all(|(a, b)| *a == -*b))
                    .expect("every link has its opposite")
            })
            .collect();
        let cs2 = e
            .iter()
            .zip(&w)
            .map(|(v, w)| w * f64::from(v[0] * v[0]))
            .sum();
        Links {
            e,
            w,
            opposite,
            cs2,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_are_normalised_isotropic_and_paired() {
        for set in [Velocities::D3q7, Velocities::D3q19] {
            let l = set.links();
            assert_eq!(l.e.len(), set.len());
            assert!((l.w.iter().sum::<f64>() - 1.0).abs() < 1e-15);
            // Σ w e_a e_b = c_s² δ_ab, Σ w e = 0.
            for a in 0..3 {
                for b in 0..3 {
                    let m: f64 =
                        l.e.iter()
                            .zip(&l.w)
                            .map(|(v, w)| w * f64::from(v[a] * v[b]))
                            .sum();
                    let want = if a == b { l.cs2 } else { 0.0 };
                    assert!((m - want).abs() < 1e-15, "{set:?} {a}{b}");
                }
                let first: f64 = l.e.iter().zip(&l.w).map(|(v, w)| w * f64::from(v[a])).sum();
                assert!(first.abs() < 1e-15);
            }
            for k in 1..l.e.len() {
                let pair = if k % 2 == 1 { k + 1 } else { k - 1 };
                assert_eq!(l.opposite[k], pair, "{set:?} link {k}");
            }
        }
        assert!((Velocities::D3q7.links().cs2 - 0.25).abs() < 1e-15);
        assert!((Velocities::D3q19.links().cs2 - 1.0 / 3.0).abs() < 1e-15);
    }
}
