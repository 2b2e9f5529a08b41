//! A box of cells on one level of the hierarchy: what a rank owns of it, and the parts of
//! it that the distributed kernels run on.

use std::ops::Range;

/// The cells [x₀, x₁) × [y₀, y₁) × [z₀, z₁) of a level (index i + n_x (j + n_y k)). A
/// z-slab is the region of whole x-lines and whole layers.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Region {
    /// Per axis, the cells it covers.
    pub axes: [Range<usize>; 3],
}

impl Region {
    /// The region of `axes`.
    pub fn new(axes: [Range<usize>; 3]) -> Self {
        Self { axes }
    }

    /// Every cell of a level of `dims`.
    pub fn whole(dims: [usize; 3]) -> Self {
        Self::layers(dims, 0..dims[2])
    }

    /// The whole layers `layers` of a level of `dims`: a z-slab.
    pub fn layers(dims: [usize; 3], layers: Range<usize>) -> Self {
        Self::new([0..dims[0], 0..dims[1], layers])
    }

    /// Whether it holds no cell.
    pub fn is_empty(&self) -> bool {
        self.axes.iter().any(|r| r.is_empty())
    }

    /// How many cells it holds.
    pub fn cells(&self) -> usize {
        self.axes.iter().map(|r| r.len()).product()
    }

    /// Its x-range.
    pub fn x(&self) -> Range<usize> {
        self.axes[0].clone()
    }

    /// Its y-range.
    pub fn y(&self) -> Range<usize> {
        self.axes[1].clone()
    }

    /// Its z-range (the layers it touches).
    pub fn z(&self) -> Range<usize> {
        self.axes[2].clone()
    }

    /// The cells it shares with `other` (empty when they do not meet).
    pub fn overlap(&self, other: &Region) -> Region {
        Region::new(std::array::from_fn(|a| {
            let (s, e) = (
                self.axes[a].start.max(other.axes[a].start),
                self.axes[a].end.min(other.axes[a].end),
            );
            s..e.max(s)
        }))
    }

    /// Grown by `by` cells on every side, within a level of `dims` (empty stays empty).
    pub fn grown(&self, by: usize, dims: [usize; 3]) -> Region {
        if self.is_empty() {
            return self.clone();
        }
        Region::new(std::array::from_fn(|a| {
            self.axes[a].start.saturating_sub(by)..(self.axes[a].end + by).min(dims[a])
        }))
    }

    /// The level index of each of its x-lines' first cell in a level of `dims` (each line
    /// x₁ − x₀ cells long): y then z, the order the grid stores them.
    pub(crate) fn lines(&self, dims: [usize; 3]) -> impl Iterator<Item = usize> + '_ {
        let [nx, ny, _] = dims;
        self.z().flat_map(move |k| {
            self.y()
                .map(move |j| self.axes[0].start + nx * (j + ny * k))
        })
    }

    /// Copies its cells of `from` into `to` (two vectors of one level).
    pub(crate) fn copy<T: Copy>(&self, dims: [usize; 3], from: &[T], to: &mut [T]) {
        let n = self.axes[0].len();
        for start in self.lines(dims) {
            to[start..start + n].copy_from_slice(&from[start..start + n]);
        }
    }

    /// Its cells of `v` (a level's vector), x-line by x-line, as they are.
    pub(crate) fn cut<T: Copy + Default>(&self, dims: [usize; 3], v: &[T]) -> Vec<T> {
        let n = self.axes[0].len();
        let mut out = vec![T::default(); self.cells()];
        if n == 0 {
            return out;
        }
        for (start, line) in self.lines(dims).zip(out.chunks_exact_mut(n)) {
            line.copy_from_slice(&v[start..start + n]);
        }
        out
    }

    /// Its values of `v` (a level's vector), x-line by x-line.
    pub(crate) fn read<T: Copy>(
        &self,
        dims: [usize; 3],
        v: &[T],
        to: impl Fn(T) -> f64,
    ) -> Vec<f64> {
        let n = self.axes[0].len();
        let mut out = vec![0.0; self.cells()];
        if n == 0 {
            return out;
        }
        for (start, line) in self.lines(dims).zip(out.chunks_exact_mut(n)) {
            for (o, &x) in line.iter_mut().zip(&v[start..start + n]) {
                *o = to(x);
            }
        }
        out
    }

    /// Writes `values` ([`Region::read`]'s order) into its cells of `v`; false (and `v`
    /// unchanged) when there are not exactly as many values as cells.
    pub(crate) fn write<T>(
        &self,
        dims: [usize; 3],
        v: &mut [T],
        values: &[f64],
        from: impl Fn(f64) -> T,
    ) -> bool {
        if values.len() != self.cells() {
            return false;
        }
        let n = self.axes[0].len();
        if n == 0 {
            return true;
        }
        for (start, line) in self.lines(dims).zip(values.chunks(n)) {
            for (x, &v) in v[start..start + n].iter_mut().zip(line) {
                *x = from(v);
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn read_and_write_are_inverse_on_the_region_and_leave_the_rest() {
        let dims = [5, 4, 3];
        let v: Vec<f32> = (0..60).map(|i| i as f32).collect();
        let r = Region::new([1..3, 2..4, 1..3]);
        let values = r.read(dims, &v, f64::from);
        assert_eq!(values.len(), r.cells());
        // The first line: (1..3, 2, 1) = 1 + 5·(2 + 4) = 31, 32.
        assert_eq!(&values[..2], &[31.0, 32.0]);
        let mut w = vec![0.0f32; 60];
        assert!(r.write(dims, &mut w, &values, |x| x as f32));
        for (g, (&a, &b)) in v.iter().zip(&w).enumerate() {
            let (i, j, k) = (g % 5, (g / 5) % 4, g / 20);
            let inside = r.x().contains(&i) && r.y().contains(&j) && r.z().contains(&k);
            assert_eq!(b, if inside { a } else { 0.0 }, "cell {g}");
        }
        assert!(!r.write(dims, &mut w, &values[1..], |x| x as f32));
    }

    #[test]
    fn overlap_and_growth_stay_within_the_level() {
        let dims = [8, 8, 8];
        let a = Region::new([0..4, 2..6, 3..8]);
        let b = Region::new([3..8, 0..3, 0..4]);
        assert_eq!(a.overlap(&b), Region::new([3..4, 2..3, 3..4]));
        assert!(a.overlap(&Region::new([4..8, 0..8, 0..8])).is_empty());
        assert_eq!(a.grown(1, dims), Region::new([0..5, 1..7, 2..8]));
        assert!(Region::default().grown(1, dims).is_empty());
    }
}
