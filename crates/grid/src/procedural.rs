//! Procedural volumes: signed distance functions of simple shapes, the densities they
//! bound, a Gaussian blob and a seeded fractal-noise cloud. SDF grids feed the
//! embedded-boundary solver; densities feed the transfer functions and the test scenes.

use glam::DVec3;

use crate::dense::Grid;
use crate::error::GridError;
use crate::geometry::GridGeometry;

/// A solid described by its exact signed distance (negative inside, scene units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// A ball.
    Sphere {
        /// Centre.
        centre: DVec3,
        /// Radius > 0.
        radius: f64,
    },
    /// An axis-aligned box.
    Box {
        /// Minimum corner.
        min: DVec3,
        /// Maximum corner (> `min` on every axis).
        max: DVec3,
    },
    /// The infinite slab of points within `thickness`/2 of the plane n·p = `offset`.
    Slab {
        /// Plane normal (normalised on use).
        normal: DVec3,
        /// Signed distance of the mid-plane from the origin along `normal`.
        offset: f64,
        /// Thickness > 0.
        thickness: f64,
    },
    /// A torus around the z axis through `centre`.
    Torus {
        /// Centre.
        centre: DVec3,
        /// Distance from the centre to the tube's centre line (> `minor`).
        major: f64,
        /// Tube radius > 0.
        minor: f64,
    },
}

impl Shape {
    /// Checks the parameters (positive sizes, finite values, non-zero normal).
    pub fn validate(&self) -> Result<(), GridError> {
        let positive = |x: f64| x > 0.0 && x.is_finite();
        let (ok, reason) = match *self {
            Shape::Sphere { centre, radius } => (
                centre.is_finite() && positive(radius),
                "sphere needs a finite centre and a positive radius",
            ),
            Shape::Box { min, max } => (
                min.is_finite() && max.is_finite() && (max - min).cmpgt(DVec3::ZERO).all(),
                "box needs finite corners with max > min",
            ),
            Shape::Slab {
                normal,
                offset,
                thickness,
            } => (
                normal.is_finite()
                    && normal.length_squared() > 0.0
                    && offset.is_finite()
                    && positive(thickness),
                "slab needs a non-zero normal, a finite offset and a positive thickness",
            ),
            Shape::Torus {
                centre,
                major,
                minor,
            } => (
                centre.is_finite() && positive(minor) && positive(major) && major > minor,
                "torus needs a finite centre and major > minor > 0",
            ),
        };
        if ok {
            Ok(())
        } else {
            Err(GridError::InvalidParameter {
                name: "shape",
                reason: reason.into(),
            })
        }
    }

    /// Exact signed distance from `p` to the surface (negative inside).
    pub fn signed_distance(&self, p: DVec3) -> f64 {
        match *self {
            Shape::Sphere { centre, radius } => (p - centre).length() - radius,
            Shape::Box { min, max } => {
                let centre = 0.5 * (min + max);
                let half = 0.5 * (max - min);
                let q = (p - centre).abs() - half;
                q.max(DVec3::ZERO).length() + q.max_element().min(0.0)
            }
            Shape::Slab {
                normal,
                offset,
                thickness,
            } => (p.dot(normal.normalize()) - offset).abs() - 0.5 * thickness,
            Shape::Torus {
                centre,
                major,
                minor,
            } => {
                let q = p - centre;
                let ring = (q.x * q.x + q.y * q.y).sqrt() - major;
                (ring * ring + q.z * q.z).sqrt() - minor
            }
        }
    }

    /// The signed distance sampled at every cell centre.
    pub fn sdf_grid(&self, geometry: GridGeometry) -> Result<Grid, GridError> {
        self.validate()?;
        Ok(Grid::from_fn(geometry, |p| self.signed_distance(p) as f32))
    }

    /// Density 1 inside and 0 outside, with a linear ramp of width `edge` across the surface
    /// (`edge` = 0 gives a hard edge decided at the cell centre).
    pub fn density_grid(&self, geometry: GridGeometry, edge: f64) -> Result<Grid, GridError> {
        self.validate()?;
        if !(edge >= 0.0 && edge.is_finite()) {
            return Err(GridError::InvalidParameter {
                name: "edge",
                reason: format!("{edge} must be finite and ≥ 0"),
            });
        }
        Ok(Grid::from_fn(geometry, |p| self.density_at(p, edge)))
    }

    /// The density [`Shape::density_grid`] gives a cell centred at `p` (`edge` ≥ 0).
    pub fn density_at(&self, p: DVec3, edge: f64) -> f32 {
        let d = self.signed_distance(p);
        if edge == 0.0 {
            f32::from(u8::from(d < 0.0))
        } else {
            (0.5 - d / edge).clamp(0.0, 1.0) as f32
        }
    }
}

/// A Gaussian blob exp(−|p − centre|²/(2σ²)) with peak 1.
pub fn gaussian_blob(geometry: GridGeometry, centre: DVec3, sigma: f64) -> Result<Grid, GridError> {
    if !(centre.is_finite() && sigma > 0.0 && sigma.is_finite()) {
        return Err(GridError::InvalidParameter {
            name: "gaussian blob",
            reason: "needs a finite centre and σ > 0".into(),
        });
    }
    Ok(Grid::from_fn(geometry, |p| {
        gaussian_blob_at(p, centre, sigma)
    }))
}

/// The value [`gaussian_blob`] gives a cell centred at `p`.
pub fn gaussian_blob_at(p: DVec3, centre: DVec3, sigma: f64) -> f32 {
    let inv = 1.0 / (2.0 * sigma * sigma);
    (-(p - centre).length_squared() * inv).exp() as f32
}

/// A seeded fractal (fBm) gradient-noise cloud inside a ball, thinning toward its edge:
/// density = max(0, fbm(p) + falloff(r) − `threshold`) · `sharpness`, clamped to [0, 1],
/// with falloff(r) = 1 − r/`radius`. The same seed gives the same cloud on every machine.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseCloud {
    /// Seed of the noise lattice.
    pub seed: u64,
    /// Centre of the cloud.
    pub centre: DVec3,
    /// Radius beyond which the density is zero.
    pub radius: f64,
    /// Frequency of the first octave (cycles per scene unit).
    pub frequency: f64,
    /// Number of octaves.
    pub octaves: u32,
    /// Frequency multiplier between octaves.
    pub lacunarity: f64,
    /// Amplitude multiplier between octaves.
    pub gain: f64,
    /// Density offset: larger values carve more empty space.
    pub threshold: f64,
    /// Density gain after thresholding.
    pub sharpness: f64,
}

impl NoiseCloud {
    /// A cumulus-like default inside the ball (`centre`, `radius`).
    pub fn new(seed: u64, centre: DVec3, radius: f64) -> Self {
        Self {
            seed,
            centre,
            radius,
            frequency: 2.0 / radius,
            octaves: 5,
            lacunarity: 2.0,
            gain: 0.5,
            threshold: 0.45,
            sharpness: 3.0,
        }
    }

    /// Density at `p`, in [0, 1].
    pub fn density(&self, p: DVec3) -> f64 {
        let r = (p - self.centre).length();
        if r >= self.radius {
            return 0.0;
        }
        let mut sum = 0.0;
        let (mut amplitude, mut frequency) = (0.5, self.frequency);
        for octave in 0..self.octaves {
            sum += amplitude
                * gradient_noise(p * frequency, self.seed.wrapping_add(u64::from(octave)));
            amplitude *= self.gain;
            frequency *= self.lacunarity;
        }
        ((sum + 1.0 - r / self.radius - self.threshold) * self.sharpness).clamp(0.0, 1.0)
    }

    /// The cloud sampled at every cell centre.
    pub fn rasterize(&self, geometry: GridGeometry) -> Result<Grid, GridError> {
        let ok = self.centre.is_finite()
            && self.radius > 0.0
            && self.radius.is_finite()
            && self.frequency.is_finite()
            && self.lacunarity.is_finite()
            && self.gain.is_finite()
            && self.threshold.is_finite()
            && self.sharpness.is_finite()
            && self.octaves <= 16;
        if !ok {
            return Err(GridError::InvalidParameter {
                name: "noise cloud",
                reason: "needs finite parameters, a positive radius and at most 16 octaves".into(),
            });
        }
        Ok(Grid::from_fn(geometry, |p| self.density(p) as f32))
    }
}

/// Perlin-style gradient noise in about [−1, 1]: pseudo-random unit gradients on the
/// integer lattice (hashed from the lattice point and the seed), blended with the quintic
/// fade 6t⁵ − 15t⁴ + 10t³.
fn gradient_noise(p: DVec3, seed: u64) -> f64 {
    let cell = p.floor();
    let f = p - cell;
    let fade = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (u, v, w) = (fade(f.x), fade(f.y), fade(f.z));
    let base = [cell.x as i64, cell.y as i64, cell.z as i64];
    let corner = |dx: i64, dy: i64, dz: i64| {
        let g = lattice_gradient(base[0] + dx, base[1] + dy, base[2] + dz, seed);
        g.dot(f - DVec3::new(dx as f64, dy as f64, dz as f64))
    };
    let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
    let x00 = lerp(corner(0, 0, 0), corner(1, 0, 0), u);
    let x10 = lerp(corner(0, 1, 0), corner(1, 1, 0), u);
    let x01 = lerp(corner(0, 0, 1), corner(1, 0, 1), u);
    let x11 = lerp(corner(0, 1, 1), corner(1, 1, 1), u);
    lerp(lerp(x00, x10, v), lerp(x01, x11, v), w)
}

/// One of the 12 edge directions of a cube (Perlin 2002), picked by a SplitMix64 hash.
fn lattice_gradient(x: i64, y: i64, z: i64, seed: u64) -> DVec3 {
    let mut h = seed ^ (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    h ^= (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    h ^= (z as u64).wrapping_mul(0x1656_67B1_9E37_79F9);
    h = (h ^ (h >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    h = (h ^ (h >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    h ^= h >> 31;
    const G: [[f64; 3]; 12] = [
        [1.0, 1.0, 0.0],
        [-1.0, 1.0, 0.0],
        [1.0, -1.0, 0.0],
        [-1.0, -1.0, 0.0],
        [1.0, 0.0, 1.0],
        [-1.0, 0.0, 1.0],
        [1.0, 0.0, -1.0],
        [-1.0, 0.0, -1.0],
        [0.0, 1.0, 1.0],
        [0.0, -1.0, 1.0],
        [0.0, 1.0, -1.0],
        [0.0, -1.0, -1.0],
    ];
    DVec3::from_array(G[(h % 12) as usize])
}
