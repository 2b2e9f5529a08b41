//! Spherical quadratures: sets of unit directions ω_m with weights w_m such that
//! ∫_{4π} f(ω) dω ≈ Σ_m w_m f(ω_m). Weights always sum to 4π, and every set here is
//! symmetric under ω → −ω, so all odd moments (the first moment Σ w_m ω_m in particular)
//! vanish to round-off.
//!
//! Three families:
//! - **Level-symmetric S_N** (N = 2, 4, …, 16; N(N+2) directions), the classical choice of
//!   discrete-ordinates codes. The direction cosines take N/2 values per axis with
//!   μ_i² = μ_1² + (i − 1)·2(1 − 3μ_1²)/(N − 2); the per-class weights and, where the
//!   moment equations determine it, μ_1 are solved here from the octahedrally invariant
//!   moment conditions (the symmetric monomials x^{2a} y^{2b} z^{2c} of the top degree)
//!   rather than copied from 7-digit tables, so every set is exact to round-off up to its
//!   [`design_degree`](SphericalQuadrature::design_degree). Where the equations leave μ_1
//!   free (S12, S16) the classical value of Lewis & Miller is used.
//! - **Octahedral, nested** (8·4^L directions: 8 ⊂ 32 ⊂ 128 ⊂ 512 …): the faces of the
//!   octahedron, recursively split into four, projected to the sphere. Each direction is
//!   the projected centroid of its cell and its weight is the cell's exact solid angle.
//!   The central child of a cell has the same centroid as its parent, so each level
//!   *contains* the previous one: the first 8·4^{L−1} directions of level L are exactly the
//!   directions of level L − 1, in the same order, and every direction knows its parent
//!   cell. This is the nested family that separate storage and propagation resolutions need
//!   (Bernabei's 8/24/48/120 counts are level-symmetric sizes, which are *not* nested:
//!   Bernabei's thesis §5.3, docs/reference-cases.md). Design degree 3, with O(h²) convergence above.
//! - **Fibonacci** (any even count): a golden-angle spiral on the upper hemisphere and its
//!   mirror image, equal weights. Design degree 1, near-uniform coverage for any count.

use std::f64::consts::PI;

use glam::DVec3;

use crate::error::OpticsError;

/// Which family a quadrature belongs to, with its parameter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QuadratureFamily {
    /// Level-symmetric S_N with this N.
    LevelSymmetric(usize),
    /// Nested octahedral at this refinement level (8·4^level directions).
    Octahedral(usize),
    /// Fibonacci spiral with this many directions.
    Fibonacci(usize),
    /// Directions and weights given by the caller, with this many directions.
    Custom(usize),
}

/// A set of directions and weights on the unit sphere.
#[derive(Debug, Clone, PartialEq)]
pub struct SphericalQuadrature {
    family: QuadratureFamily,
    directions: Vec<DVec3>,
    weights: Vec<f64>,
    design_degree: u32,
}

/// Classical μ_1 of the level-symmetric LQ_N sets (Lewis & Miller, *Computational Methods
/// of Neutron Transport*, table 4-1), indexed by N/2 − 1. Used as the starting point of the
/// solve, and as the value itself where the moment equations leave μ_1 free.
const CLASSICAL_MU1: [f64; 8] = [
    0.577_350_3,
    0.350_021_2,
    0.266_635_5,
    0.218_217_9,
    0.189_321_3,
    0.167_212_6,
    0.151_985_9,
    0.138_956_8,
];

/// The deepest nested octahedral level offered (8·4⁶ = 32 768 directions).
pub const MAX_OCTAHEDRAL_LEVEL: usize = 6;

impl SphericalQuadrature {
    /// The level-symmetric S_N set with N(N+2) directions, N ∈ {2, 4, …, 16}.
    ///
    /// ```
    /// use lucent_optics::SphericalQuadrature;
    /// let s8 = SphericalQuadrature::level_symmetric(8)?;
    /// assert_eq!(s8.len(), 80);
    /// // ∫ ω_z⁸ dω = 4π/9, exact because the design degree is 9.
    /// let z8 = s8.integrate(|d| d.z.powi(8));
    /// assert!((z8 - 4.0 * std::f64::consts::PI / 9.0).abs() < 1e-13);
    /// # Ok::<(), lucent_optics::OpticsError>(())
    /// ```
    ///
    /// | N | directions | design degree |
    /// |---|---|---|
    /// | 2 | 8 | 3 |
    /// | 4 | 24 | 5 |
    /// | 6 | 48 | 7 |
    /// | 8 | 80 | 9 |
    /// | 10 | 120 | 11 |
    /// | 12 | 168 | 11 |
    /// | 14 | 224 | 15 |
    /// | 16 | 288 | 15 |
    pub fn level_symmetric(n: usize) -> Result<Self, OpticsError> {
        if !(2..=16).contains(&n) || n % 2 == 1 {
            return Err(OpticsError::UnsupportedQuadrature {
                family: "level-symmetric",
                order: n,
                reason: "N must be even and between 2 and 16",
            });
        }
        let levels = n / 2;
        let points = level_points(levels);
        let classes = weight_classes(&points);
        // Degree of the moment conditions imposed, and whether μ1 is solved for.
        let (degree, solve_mu1) = match n {
            2 => (2, false),
            12 => (10, false),
            16 => (14, false),
            _ => (n, true),
        };
        let conditions = symmetric_exponents(degree / 2);
        let mu1 = if solve_mu1 {
            solve_mu1_for_consistency(
                levels,
                &points,
                &classes,
                &conditions,
                CLASSICAL_MU1[levels - 1],
            )
        } else if n == 2 {
            1.0 / 3f64.sqrt()
        } else {
            CLASSICAL_MU1[levels - 1]
        };
        let cosines = level_cosines(levels, mu1);
        let class_weights = solve_class_weights(&cosines, &points, &classes, &conditions);
        let mut directions = Vec::with_capacity(8 * points.len());
        let mut weights = Vec::with_capacity(8 * points.len());
        for octant in 0..8 {
            let sign = octant_sign(octant);
            for (p, &(i, j, k)) in points.iter().enumerate() {
                directions.push(sign * DVec3::new(cosines[i], cosines[j], cosines[k]));
                weights.push(class_weights[classes[p]]);
            }
        }
        Ok(Self {
            family: QuadratureFamily::LevelSymmetric(n),
            directions,
            weights,
            design_degree: degree as u32 + 1,
        })
    }

    /// The nested octahedral set at refinement `level` ≤ [`MAX_OCTAHEDRAL_LEVEL`], with
    /// 8·4^level directions. See the module docs for the nesting guarantee.
    pub fn octahedral(level: usize) -> Result<Self, OpticsError> {
        if level > MAX_OCTAHEDRAL_LEVEL {
            return Err(OpticsError::UnsupportedQuadrature {
                family: "octahedral",
                order: level,
                reason: "the refinement level must be at most 6 (32768 directions)",
            });
        }
        let cells = octahedral_cells(level);
        let directions = cells
            .iter()
            .map(|[a, b, c]| (*a + *b + *c).normalize())
            .collect();
        let weights = cells
            .iter()
            .map(|[a, b, c]| solid_angle(*a, *b, *c))
            .collect();
        Ok(Self {
            family: QuadratureFamily::Octahedral(level),
            directions,
            weights,
            design_degree: 3,
        })
    }

    /// The index, in level `level − 1`, of the cell that contains direction `index` of
    /// level `level` (`None` for level 0 or an index out of range). Children that lie in
    /// the centre of their parent keep its index; the others are numbered after them, three
    /// per parent.
    pub fn octahedral_parent(level: usize, index: usize) -> Option<usize> {
        if level == 0 || level > MAX_OCTAHEDRAL_LEVEL {
            return None;
        }
        let coarse = 8 << (2 * (level - 1));
        match index {
            i if i < coarse => Some(i),
            i if i < 4 * coarse => Some((i - coarse) / 3),
            _ => None,
        }
    }

    /// A Fibonacci (golden-angle) set of `count` directions, `count` even and ≥ 2, with
    /// equal weights 4π/count. The upper hemisphere holds the spiral
    /// z_i = 1 − (2i + 1)/count, φ_i = 2π i/ϕ; the lower one its mirror image −ω_i.
    pub fn fibonacci(count: usize) -> Result<Self, OpticsError> {
        if count < 2 || count % 2 == 1 {
            return Err(OpticsError::UnsupportedQuadrature {
                family: "Fibonacci",
                order: count,
                reason: "the count must be even and at least 2",
            });
        }
        let golden = 0.5 * (1.0 + 5f64.sqrt());
        let n = count as f64;
        let upper: Vec<DVec3> = (0..count / 2)
            .map(|i| {
                let z = 1.0 - (2.0 * i as f64 + 1.0) / n;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let (s, c) = (2.0 * PI * (i as f64 / golden).fract()).sin_cos();
                DVec3::new(r * c, r * s, z)
            })
            .collect();
        let directions = upper
            .iter()
            .copied()
            .chain(upper.iter().map(|&d| -d))
            .collect();
        Ok(Self {
            family: QuadratureFamily::Fibonacci(count),
            directions,
            weights: vec![4.0 * PI / n; count],
            design_degree: 1,
        })
    }

    /// A set given by the caller (for tests along chosen directions, or sets from other
    /// codes): unit directions and positive weights summing to 4π (to 10⁻¹²), at least two
    /// directions. The design degree is taken as 0 (nothing is assumed).
    ///
    /// ```
    /// use glam::DVec3;
    /// use lucent_optics::SphericalQuadrature;
    /// // The six axis directions.
    /// let axes = [DVec3::X, -DVec3::X, DVec3::Y, -DVec3::Y, DVec3::Z, -DVec3::Z];
    /// let q = SphericalQuadrature::custom(axes.to_vec(), vec![4.0 * std::f64::consts::PI / 6.0; 6])?;
    /// assert_eq!(q.len(), 6);
    /// # Ok::<(), lucent_optics::OpticsError>(())
    /// ```
    pub fn custom(directions: Vec<DVec3>, weights: Vec<f64>) -> Result<Self, OpticsError> {
        let unsupported = |reason| OpticsError::UnsupportedQuadrature {
            family: "custom",
            order: directions.len(),
            reason,
        };
        if directions.len() < 2 || directions.len() != weights.len() {
            return Err(unsupported("at least two directions, one weight each"));
        }
        if directions
            .iter()
            .any(|d| !d.is_finite() || (d.length() - 1.0).abs() > 1e-12)
        {
            return Err(unsupported("directions must be unit vectors"));
        }
        if weights.iter().any(|w| !(w.is_finite() && *w > 0.0)) {
            return Err(unsupported("weights must be positive and finite"));
        }
        let total: f64 = weights.iter().sum();
        if (total / (4.0 * PI) - 1.0).abs() > 1e-12 {
            return Err(unsupported("weights must sum to 4π"));
        }
        Ok(Self {
            family: QuadratureFamily::Custom(directions.len()),
            directions,
            weights,
            design_degree: 0,
        })
    }

    /// The family and its parameter.
    pub fn family(&self) -> QuadratureFamily {
        self.family
    }

    /// Number of directions.
    pub fn len(&self) -> usize {
        self.directions.len()
    }

    /// Always false: every quadrature has at least two directions.
    pub fn is_empty(&self) -> bool {
        self.directions.is_empty()
    }

    /// The unit directions ω_m.
    pub fn directions(&self) -> &[DVec3] {
        &self.directions
    }

    /// The weights w_m (steradians), summing to 4π.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// The highest total degree d such that every polynomial in (ω_x, ω_y, ω_z) of degree
    /// ≤ d is integrated exactly (up to round-off).
    pub fn design_degree(&self) -> u32 {
        self.design_degree
    }

    /// Σ_m w_m f(ω_m), accumulated in f64.
    pub fn integrate(&self, mut f: impl FnMut(DVec3) -> f64) -> f64 {
        self.directions
            .iter()
            .zip(&self.weights)
            .map(|(&d, &w)| w * f(d))
            .sum()
    }

    /// The octant of direction `m` as a bit mask: bit 0 set when ω_x < 0, bit 1 when
    /// ω_y < 0, bit 2 when ω_z < 0. Sweeps group directions by octant. No direction of
    /// the built-in sets lies on a coordinate plane; a custom one that does counts a zero
    /// component as positive.
    pub fn octant(&self, m: usize) -> usize {
        let d = self.directions[m];
        usize::from(d.x < 0.0) | usize::from(d.y < 0.0) << 1 | usize::from(d.z < 0.0) << 2
    }
}

/// The sign vector of an octant index (bit set = negative component).
fn octant_sign(octant: usize) -> DVec3 {
    let s = |bit: usize| if octant >> bit & 1 == 1 { -1.0 } else { 1.0 };
    DVec3::new(s(0), s(1), s(2))
}

/// Level indices (i, j, k), 0-based, of the points of one octant: i + j + k = levels − 1.
fn level_points(levels: usize) -> Vec<(usize, usize, usize)> {
    let mut points = Vec::new();
    for i in 0..levels {
        for j in 0..levels - i {
            points.push((i, j, levels - 1 - i - j));
        }
    }
    points
}

/// Assigns each point its weight class: points whose index multisets agree are images of
/// each other under axis permutations and share a weight.
fn weight_classes(points: &[(usize, usize, usize)]) -> Vec<usize> {
    let mut keys: Vec<[usize; 3]> = Vec::new();
    points
        .iter()
        .map(|&(i, j, k)| {
            let mut key = [i, j, k];
            key.sort_unstable();
            match keys.iter().position(|&k| k == key) {
                Some(c) => c,
                None => {
                    keys.push(key);
                    keys.len() - 1
                }
            }
        })
        .collect()
}

/// The N/2 direction cosines μ_i with μ_i² = μ_1² + i·Δ, Δ = 2(1 − 3μ_1²)/(N − 2).
fn level_cosines(levels: usize, mu1: f64) -> Vec<f64> {
    if levels == 1 {
        return vec![mu1];
    }
    let delta = 2.0 * (1.0 - 3.0 * mu1 * mu1) / (2.0 * levels as f64 - 2.0);
    (0..levels)
        .map(|i| (mu1 * mu1 + i as f64 * delta).sqrt())
        .collect()
}

/// Exponent triples a ≥ b ≥ c ≥ 0 with a + b + c = `half_degree`: the symmetric monomials
/// x^{2a} y^{2b} z^{2c} of degree 2·`half_degree`. On the sphere they form a basis of the
/// octahedrally invariant polynomials of degree ≤ 2·`half_degree` (lower degrees follow by
/// multiplying with x² + y² + z² = 1), so imposing them imposes every lower condition too.
fn symmetric_exponents(half_degree: usize) -> Vec<[u32; 3]> {
    let mut out = Vec::new();
    for a in (0..=half_degree).rev() {
        for b in (0..=a.min(half_degree - a)).rev() {
            let c = half_degree - a - b;
            if c <= b {
                out.push([a as u32, b as u32, c as u32]);
            }
        }
    }
    out
}

/// ∫_{S²} x^{2a} y^{2b} z^{2c} dω = 4π (2a−1)!!(2b−1)!!(2c−1)!!/(2(a+b+c)+1)!!.
fn sphere_moment([a, b, c]: [u32; 3]) -> f64 {
    let double_factorial_odd = |k: u32| (1..=k).map(|i| (2 * i - 1) as f64).product::<f64>();
    4.0 * PI * double_factorial_odd(a) * double_factorial_odd(b) * double_factorial_odd(c)
        / double_factorial_odd(a + b + c + 1)
}

/// The moment matrix: row per condition, column per weight class, entry = 8 × (sum over the
/// class's points in one octant of the monomial), so that Σ_c A[r][c] w_c = ∫ monomial_r.
fn moment_matrix(
    cosines: &[f64],
    points: &[(usize, usize, usize)],
    classes: &[usize],
    conditions: &[[u32; 3]],
) -> Vec<Vec<f64>> {
    let class_count = classes.iter().max().map_or(0, |m| m + 1);
    conditions
        .iter()
        .map(|&[a, b, c]| {
            let mut row = vec![0.0; class_count];
            for (p, &(i, j, k)) in points.iter().enumerate() {
                row[classes[p]] += 8.0
                    * cosines[i].powi(2 * a as i32)
                    * cosines[j].powi(2 * b as i32)
                    * cosines[k].powi(2 * c as i32);
            }
            row
        })
        .collect()
}

/// Least-squares class weights for the given μ's (Householder QR; the systems are at most
/// 10 × 8 and consistent, so the residual is round-off).
fn solve_class_weights(
    cosines: &[f64],
    points: &[(usize, usize, usize)],
    classes: &[usize],
    conditions: &[[u32; 3]],
) -> Vec<f64> {
    let a = moment_matrix(cosines, points, classes, conditions);
    let b: Vec<f64> = conditions.iter().map(|&e| sphere_moment(e)).collect();
    least_squares(a, b)
}

/// When the conditions outnumber the weight classes by one, the augmented matrix [A | b]
/// is square and the system is consistent exactly where its determinant vanishes: find
/// that μ_1 by bracketing around the classical value and bisecting to round-off.
fn solve_mu1_for_consistency(
    levels: usize,
    points: &[(usize, usize, usize)],
    classes: &[usize],
    conditions: &[[u32; 3]],
    guess: f64,
) -> f64 {
    let det = |mu1: f64| {
        let cosines = level_cosines(levels, mu1);
        let mut m = moment_matrix(&cosines, points, classes, conditions);
        for (row, &e) in m.iter_mut().zip(conditions) {
            row.push(sphere_moment(e));
        }
        determinant(m)
    };
    // The classical μ1 is good to 1e-7; widen the bracket until the sign changes.
    let (mut lo, mut hi) = (guess - 1e-4, guess + 1e-4);
    let mut width = 1e-4;
    while det(lo).signum() == det(hi).signum() && width < 0.05 {
        width *= 2.0;
        lo = guess - width;
        hi = (guess + width).min(1.0 / 3f64.sqrt() - 1e-9);
    }
    let f_lo = det(lo);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid <= lo || mid >= hi {
            break;
        }
        if det(mid).signum() == f_lo.signum() {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Determinant by Gaussian elimination with partial pivoting.
fn determinant(mut m: Vec<Vec<f64>>) -> f64 {
    let n = m.len();
    let mut det = 1.0;
    for col in 0..n {
        let pivot = (col..n)
            .max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))
            .unwrap_or(col);
        if m[pivot][col] == 0.0 {
            return 0.0;
        }
        if pivot != col {
            m.swap(pivot, col);
            det = -det;
        }
        det *= m[col][col];
        for row in col + 1..n {
            let factor = m[row][col] / m[col][col];
            for k in col..n {
                m[row][k] -= factor * m[col][k];
            }
        }
    }
    det
}

/// Solves min ‖Ax − b‖ for a tall, full-column-rank A by Householder QR.
fn least_squares(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Vec<f64> {
    let rows = a.len();
    let cols = a.first().map_or(0, Vec::len);
    for k in 0..cols {
        let norm = (k..rows).map(|i| a[i][k] * a[i][k]).sum::<f64>().sqrt();
        if norm == 0.0 {
            continue;
        }
        let alpha = if a[k][k] > 0.0 { -norm } else { norm };
        let mut v: Vec<f64> = (k..rows).map(|i| a[i][k]).collect();
        v[0] -= alpha;
        let vv: f64 = v.iter().map(|x| x * x).sum();
        if vv == 0.0 {
            continue;
        }
        for j in k..cols {
            let s: f64 = (k..rows).map(|i| v[i - k] * a[i][j]).sum::<f64>() * 2.0 / vv;
            for i in k..rows {
                a[i][j] -= s * v[i - k];
            }
        }
        let s: f64 = (k..rows).map(|i| v[i - k] * b[i]).sum::<f64>() * 2.0 / vv;
        for i in k..rows {
            b[i] -= s * v[i - k];
        }
    }
    let mut x = vec![0.0; cols];
    for k in (0..cols).rev() {
        let s: f64 = (k + 1..cols).map(|j| a[k][j] * x[j]).sum();
        x[k] = (b[k] - s) / a[k][k];
    }
    x
}

/// The flat triangles of the octahedron's faces after `level` 4-way splits, ordered so that
/// the first 8·4^{level−1} are the central children of the previous level's cells (same
/// centroid, same order) and the rest follow three per parent.
fn octahedral_cells(level: usize) -> Vec<[DVec3; 3]> {
    let mut cells: Vec<[DVec3; 3]> = (0..8)
        .map(|octant| {
            let s = octant_sign(octant);
            [
                DVec3::new(s.x, 0.0, 0.0),
                DVec3::new(0.0, s.y, 0.0),
                DVec3::new(0.0, 0.0, s.z),
            ]
        })
        .collect();
    for _ in 0..level {
        let mut central = Vec::with_capacity(cells.len());
        let mut corners = Vec::with_capacity(3 * cells.len());
        for [a, b, c] in cells {
            let (ab, bc, ca) = (0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a));
            central.push([ab, bc, ca]);
            corners.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c]]);
        }
        central.extend(corners);
        cells = central;
    }
    cells
}

/// Solid angle of the spherical triangle spanned by the radial projections of a, b, c
/// (Van Oosterom & Strackee 1983): tan(Ω/2) = |â·(b̂×ĉ)| / (1 + â·b̂ + b̂·ĉ + ĉ·â).
fn solid_angle(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let (a, b, c) = (a.normalize(), b.normalize(), c.normalize());
    let numerator = a.dot(b.cross(c)).abs();
    let denominator = 1.0 + a.dot(b) + b.dot(c) + c.dot(a);
    2.0 * numerator.atan2(denominator)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn symmetric_exponent_counts_match_the_octahedral_invariants() {
        // Number of O_h-invariant polynomials of degree ≤ 2k on the sphere (Molien series).
        let expected = [1, 1, 2, 3, 4, 5, 7, 8, 10];
        for (k, &count) in expected.iter().enumerate() {
            assert_eq!(symmetric_exponents(k).len(), count, "degree {}", 2 * k);
        }
    }

    #[test]
    fn octahedral_parent_indices_point_to_containing_cells() {
        for level in 1..=3 {
            let fine = SphericalQuadrature::octahedral(level).unwrap();
            let coarse_cells = octahedral_cells(level - 1);
            for (m, d) in fine.directions().iter().enumerate() {
                let [a, b, c] =
                    coarse_cells[SphericalQuadrature::octahedral_parent(level, m).unwrap()];
                // Inside the spherical triangle: on the inner side of all three great circles.
                let n = a.cross(b).dot(c).signum();
                for (p, q) in [(a, b), (b, c), (c, a)] {
                    assert!(n * p.cross(q).dot(*d) > 0.0, "level {level}, direction {m}");
                }
            }
        }
    }
}
