//! **Parallelism.** Triangles are cut into fixed chunks; each chunk sums into its own
//! accumulators, which are then added in chunk order: the result is the same, bit for bit,
//! whatever the number of threads.

use super::lanes::{Lanes, Points, LANES};
use super::prism::prism_volumes;
use super::{DiceAttachment, Ends, Sample};
use crate::flow::kernel::Isa;
use crate::Vec3;

/// Partial sums of one chunk of triangles.
pub(super) struct ChunkSums {
    pub(super) volume: f64,
    pub(super) overlap: f64,
    pub(super) negative: f64,
    /// `∂O/∂q` and `∂V_abs/∂q`, `V_abs = Σ |vol_P|` (empty when no gradient is wanted).
    pub(super) grad_overlap: Vec<Vec3>,
    pub(super) grad_volume: Vec<Vec3>,
}

impl DiceAttachment {
    /// The sums over the prisms of the triangles `tris`, on the widest instruction set the CPU
    /// has ([`Isa`]: the same bits on each).
    pub(super) fn chunk_sums(
        &self,
        tris: &[usize],
        ends: &[Ends],
        samples: &[Sample],
        want_grad: bool,
    ) -> ChunkSums {
        match Isa::best() {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: the running CPU supports AVX-512F (`Isa::best` checked it).
            Isa::Avx512 => unsafe { self.chunk_sums_avx512(tris, ends, samples, want_grad) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: the running CPU supports AVX2 and FMA (`Isa::best` checked it).
            Isa::Avx2Fma => unsafe { self.chunk_sums_avx2(tris, ends, samples, want_grad) },
            Isa::Portable => self.chunk_sums_with(tris, ends, samples, want_grad),
            #[cfg(not(target_arch = "x86_64"))]
            _ => self.chunk_sums_with(tris, ends, samples, want_grad),
        }
    }

    /// [`Self::chunk_sums_with`] compiled for AVX-512F.
    ///
    /// # Safety
    /// The CPU must support AVX-512F.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx2,fma")]
    unsafe fn chunk_sums_avx512(
        &self,
        tris: &[usize],
        ends: &[Ends],
        samples: &[Sample],
        want_grad: bool,
    ) -> ChunkSums {
        self.chunk_sums_with(tris, ends, samples, want_grad)
    }

    /// [`Self::chunk_sums_with`] compiled for AVX2.
    ///
    /// # Safety
    /// The CPU must support AVX2 and FMA.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn chunk_sums_avx2(
        &self,
        tris: &[usize],
        ends: &[Ends],
        samples: &[Sample],
        want_grad: bool,
    ) -> ChunkSums {
        self.chunk_sums_with(tris, ends, samples, want_grad)
    }

    #[inline(always)]
    fn chunk_sums_with(
        &self,
        tris: &[usize],
        ends: &[Ends],
        samples: &[Sample],
        want_grad: bool,
    ) -> ChunkSums {
        let mut sums = ChunkSums::zero(if want_grad { self.landmark_count } else { 0 });
        for &t in tris {
            self.triangle_sums(t, ends, samples, want_grad, &mut sums);
        }
        sums
    }

    /// Adds the prisms over subdivided triangle `t` (all layers) to `sums`: their volumes and
    /// gradients [`LANES`] layers at a time, then each layer's terms in layer order.
    #[inline(always)]
    fn triangle_sums(
        &self,
        t: usize,
        ends: &[Ends],
        samples: &[Sample],
        want_grad: bool,
        sums: &mut ChunkSums,
    ) {
        let nv = self.stencils.len();
        let tri = self.triangles[t];
        // (Arrays written out: `array::map` and `from_fn` here are compiled out of line.)
        let corner_ends = [&ends[tri[0]], &ends[tri[1]], &ends[tri[2]]];
        let mut vertex = VertexGradients::default();
        for first in (0..self.layers).step_by(LANES) {
            // Lanes past the last layer repeat it; their results are not used.
            let (mut s_lower, mut s_upper): (Lanes, Lanes) = ([0.0; LANES], [0.0; LANES]);
            for l in 0..LANES {
                let layer = (first + l).min(self.layers - 1);
                s_lower[l] = self.sheet(layer);
                s_upper[l] = self.sheet(layer + 1);
            }
            let [a, b, c] = corner_ends;
            let x = [
                Points::along(a, &s_lower),
                Points::along(b, &s_lower),
                Points::along(c, &s_lower),
                Points::along(a, &s_upper),
                Points::along(b, &s_upper),
                Points::along(c, &s_upper),
            ];
            let (vols, dvols) = prism_volumes(&x, self.faces[t].as_slice());
            for l in 0..LANES.min(self.layers - first) {
                let i = first + l;
                let (s_lower, s_upper, vol) = (s_lower[l], s_upper[l], vols[l]);
                let row = &samples[i * nv..(i + 1) * nv];
                let mid = [&row[tri[0]], &row[tri[1]], &row[tri[2]]];
                let mean_f = mid.iter().map(|s| s.f).sum::<f64>() / 3.0;
                sums.volume += vol;
                sums.overlap += vol * mean_f;
                sums.negative += vol.min(0.0);
                if want_grad {
                    let dvol = [
                        dvols[0].lane(l),
                        dvols[1].lane(l),
                        dvols[2].lane(l),
                        dvols[3].lane(l),
                        dvols[4].lane(l),
                        dvols[5].lane(l),
                    ];
                    // ∂|vol| = sign(vol) ∂vol: a folded prism adds to the denominator.
                    let sign = if vol < 0.0 { -1.0 } else { 1.0 };
                    for j in 0..3 {
                        vertex.add(j, s_lower, mean_f * dvol[j], sign * dvol[j]);
                        vertex.add(j, s_upper, mean_f * dvol[j + 3], sign * dvol[j + 3]);
                        let s_mid = s_lower + self.half_layer();
                        vertex.add_overlap(j, s_mid, vol / 3.0 * mid[j].grad_f);
                    }
                }
            }
        }
        if want_grad {
            for (j, &v) in tri.iter().enumerate() {
                self.stencils[v].scatter(&vertex.overlap[j].ends(), &mut sums.grad_overlap);
                self.stencils[v].scatter(&vertex.volume[j].ends(), &mut sums.grad_volume);
            }
        }
    }
}

/// `∂O` and `∂V` with respect to the boundary and medial points of the three vertices `j` of a
/// subdivided triangle.
#[derive(Clone, Copy, Debug, Default)]
struct VertexGradients {
    overlap: [Along; 3],
    volume: [Along; 3],
}

/// A gradient `Σ_x ∂/∂x` over points `x = (1 − s) b + s m` between a boundary point `b` and its
/// medial point `m`, kept as `Σ ∂/∂x` and `Σ s ∂/∂x`: then `∂/∂m = Σ s ∂/∂x` and
/// `∂/∂b = Σ ∂/∂x − ∂/∂m`, two vector updates per point instead of four.
#[derive(Clone, Copy, Debug, Default)]
struct Along {
    sum: Vec3,
    weighted: Vec3,
}

impl Along {
    fn add(&mut self, s: f64, d: Vec3) {
        self.sum += d;
        self.weighted += s * d;
    }

    /// `[∂/∂b, ∂/∂m]`.
    fn ends(&self) -> [Vec3; 2] {
        [self.sum - self.weighted, self.weighted]
    }
}

impl VertexGradients {
    /// Adds `∂O/∂x` and `∂V_abs/∂x` at the point `x = (1 − s) b + s m` above vertex `j`.
    fn add(&mut self, j: usize, s: f64, d_overlap: Vec3, d_volume: Vec3) {
        self.overlap[j].add(s, d_overlap);
        self.volume[j].add(s, d_volume);
    }

    /// Adds `∂O/∂x` alone (an image sample, which the volume does not depend on).
    fn add_overlap(&mut self, j: usize, s: f64, d_overlap: Vec3) {
        self.overlap[j].add(s, d_overlap);
    }
}

impl ChunkSums {
    pub(super) fn zero(gradient_len: usize) -> Self {
        Self {
            volume: 0.0,
            overlap: 0.0,
            negative: 0.0,
            grad_overlap: vec![Vec3::zeros(); gradient_len],
            grad_volume: vec![Vec3::zeros(); gradient_len],
        }
    }

    /// `self + other` (used in chunk order).
    pub(super) fn add(mut self, other: Self) -> Self {
        self.volume += other.volume;
        self.overlap += other.overlap;
        self.negative += other.negative;
        for (a, b) in self.grad_overlap.iter_mut().zip(&other.grad_overlap) {
            *a += b;
        }
        for (a, b) in self.grad_volume.iter_mut().zip(&other.grad_volume) {
            *a += b;
        }
        self
    }
}

#[cfg(test)]
mod tests {
    use super::super::{DiceAttachment, DiceParams, Ends};
    use super::*;
    use crate::image::rasterize::{grid_around, rasterize};
    use crate::synth::{Shape, SyntheticCase};

    /// The sums over every triangle of the cup, moved a little off its own rasterization, on
    /// each instruction set the CPU has: the same bits (`layers` 5 and 11: one lane block with
    /// three idle lanes, and two blocks).
    #[test]
    fn every_instruction_set_gives_the_same_bits() {
        let template = SyntheticCase::build(Shape::Cup)
            .unwrap()
            .projection
            .template;
        let boundary = template.boundary_mesh().unwrap();
        let (dims, grid) = grid_around(&boundary, 0.5, 2.0).unwrap();
        let image = rasterize(&boundary, dims, grid)
            .unwrap()
            .smoothed(0.3)
            .unwrap();
        let q: Vec<Vec3> = (template.landmarks().iter())
            .map(|p| p + Vec3::new(0.3 * (0.2 * p.y).sin(), 0.1, -0.2))
            .collect();
        for layers in [5, 11] {
            let params = DiceParams {
                subdivision: 1,
                layers,
            };
            let dice = DiceAttachment::for_template(&template, image.clone(), params).unwrap();
            let ends: Vec<Ends> = (dice.stencils.iter())
                .map(|s| Ends {
                    boundary: s.boundary.apply(&q),
                    medial: s.medial.apply(&q),
                })
                .collect();
            let samples = dice.samples(&ends, true);
            let tris: Vec<usize> = (0..dice.triangles.len()).collect();
            let bits = |s: &ChunkSums| {
                let mut b = vec![
                    s.volume.to_bits(),
                    s.overlap.to_bits(),
                    s.negative.to_bits(),
                ];
                for g in s.grad_overlap.iter().chain(&s.grad_volume) {
                    b.extend(g.iter().map(|x| x.to_bits()));
                }
                b
            };
            let baseline = bits(&dice.chunk_sums_with(&tris, &ends, &samples, true));
            assert_eq!(
                bits(&dice.chunk_sums(&tris, &ends, &samples, true)),
                baseline
            );
            #[cfg(target_arch = "x86_64")]
            for isa in [Isa::Avx2Fma, Isa::Avx512]
                .into_iter()
                .filter(|i| i.is_supported())
            {
                // SAFETY: the CPU supports `isa`, checked just above.
                let sums = unsafe {
                    match isa {
                        Isa::Avx512 => dice.chunk_sums_avx512(&tris, &ends, &samples, true),
                        _ => dice.chunk_sums_avx2(&tris, &ends, &samples, true),
                    }
                };
                assert_eq!(bits(&sums), baseline, "{isa:?}, {layers} layers");
            }
        }
    }
}
