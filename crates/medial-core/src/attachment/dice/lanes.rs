//! The layers of prisms over one subdivided triangle, eight at a time: points and numbers as
//! arrays of [`LANES`] values, one per layer, in plain per-lane loops that the compiler turns
//! into vector instructions (one AVX-512 register, two AVX2 ones or four SSE2 ones, whichever
//! the CPU has: the kernel's [`Isa`](crate::flow::kernel::Isa) picks at run time). Each lane
//! does the operations of the scalar formulas in the same order, and Rust never fuses a
//! multiply and an add on its own, so the results are the same bits on every instruction set
//! (unlike the kernel's lanes, whose intrinsics fuse them). Plain arrays rather than a SIMD
//! crate: the compiler vectorizes these loops, and the dispatch is the kernel's.

use super::sampling::Ends;
use crate::Vec3;

/// Layers computed together.
pub(super) const LANES: usize = 8;

/// One number per layer.
pub(super) type Lanes = [f64; LANES];

/// `f(a[l], b[l])` for every lane.
#[inline(always)]
fn zip(a: &Lanes, b: &Lanes, f: impl Fn(f64, f64) -> f64) -> Lanes {
    let mut out = [0.0; LANES];
    for l in 0..LANES {
        out[l] = f(a[l], b[l]);
    }
    out
}

/// A point per layer, as three arrays of coordinates.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Points {
    x: Lanes,
    y: Lanes,
    z: Lanes,
}

impl Points {
    /// `(1 − s_l) b + s_l m` for each lane's `s_l` (as [`Ends::at`] computes it).
    #[inline(always)]
    pub(super) fn along(ends: &Ends, s: &Lanes) -> Self {
        let (b, m) = (ends.boundary, ends.medial);
        let at = |bc: f64, mc: f64| {
            let mut out = [0.0; LANES];
            for l in 0..LANES {
                out[l] = (1.0 - s[l]) * bc + s[l] * mc;
            }
            out
        };
        Self {
            x: at(b.x, m.x),
            y: at(b.y, m.y),
            z: at(b.z, m.z),
        }
    }

    /// The points `p`, one per lane.
    #[cfg(test)]
    pub(super) fn of(p: [Vec3; LANES]) -> Self {
        Self {
            x: p.map(|v| v.x),
            y: p.map(|v| v.y),
            z: p.map(|v| v.z),
        }
    }

    /// Lane `l` as a vector.
    #[inline(always)]
    pub(super) fn lane(&self, l: usize) -> Vec3 {
        Vec3::new(self.x[l], self.y[l], self.z[l])
    }

    /// `self − other`, per lane.
    #[inline(always)]
    pub(super) fn sub(&self, other: &Self) -> Self {
        Self {
            x: zip(&self.x, &other.x, |a, b| a - b),
            y: zip(&self.y, &other.y, |a, b| a - b),
            z: zip(&self.z, &other.z, |a, b| a - b),
        }
    }

    /// `self += other`, per lane.
    #[inline(always)]
    pub(super) fn add_assign(&mut self, other: &Self) {
        *self = Self {
            x: zip(&self.x, &other.x, |a, b| a + b),
            y: zip(&self.y, &other.y, |a, b| a + b),
            z: zip(&self.z, &other.z, |a, b| a + b),
        };
    }

    /// `self / d`, per lane.
    #[inline(always)]
    pub(super) fn div(&self, d: f64) -> Self {
        let d = [d; LANES];
        Self {
            x: zip(&self.x, &d, |a, b| a / b),
            y: zip(&self.y, &d, |a, b| a / b),
            z: zip(&self.z, &d, |a, b| a / b),
        }
    }

    /// `self × other`, per lane (nalgebra's order: `(a_y b_z − a_z b_y, a_z b_x − a_x b_z,
    /// a_x b_y − a_y b_x)`).
    #[inline(always)]
    pub(super) fn cross(&self, o: &Self) -> Self {
        let mut out = Self::default();
        for l in 0..LANES {
            out.x[l] = self.y[l] * o.z[l] - self.z[l] * o.y[l];
            out.y[l] = self.z[l] * o.x[l] - self.x[l] * o.z[l];
            out.z[l] = self.x[l] * o.y[l] - self.y[l] * o.x[l];
        }
        out
    }

    /// `self · other`, per lane (`(a_x b_x + a_y b_y) + a_z b_z`).
    #[inline(always)]
    pub(super) fn dot(&self, o: &Self) -> Lanes {
        let mut out = [0.0; LANES];
        for (l, d) in out.iter_mut().enumerate() {
            *d = self.x[l] * o.x[l] + self.y[l] * o.y[l] + self.z[l] * o.z[l];
        }
        out
    }
}
