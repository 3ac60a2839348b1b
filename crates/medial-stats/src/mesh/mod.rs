//! The mesh the elements live on: its geometry for inference (element areas, which elements
//! touch) and the operations that use it.
//!
//! Elements are the mesh's points or its triangles ([`Support`]). Points at the same position
//! are one place of the sheet (a seam written twice): they are neighbours of each other, and
//! triangles that share an edge through them are neighbours, so that clusters and smoothing
//! follow the sheet across seams.
//!
//! | file | what it holds |
//! |---|---|
//! | `elements` | [`Mesh`], [`Support`], [`Elements`]: areas, adjacency, the diffusion operator |
//! | `forest` | union–find with component extents and additive values, shared by clusters and TFCE |
//! | `clusters` | connected supra-threshold clusters: extent (area, mm²) and mass; their outlines |
//! | `tfce` | threshold-free cluster enhancement |
//! | `smooth` | heat diffusion with a FWHM in mm |

mod clusters;
mod elements;
mod forest;
mod smooth;
mod tfce;

pub(crate) use clusters::largest_extents;
pub use clusters::{cluster_outlines, find_clusters, Cluster, Clusters};
pub use elements::{Elements, Mesh, Support};
pub(crate) use forest::Forest;
pub use smooth::{diffusion_time, smooth};
pub use tfce::{tfce, TfceParameters};
pub(crate) use tfce::{tfce_into, TfceScratch};

#[cfg(test)]
pub(crate) mod tests {
    use super::{Elements, Mesh};

    /// An n × n grid of squares cut into triangles, its points moved off the lattice so that
    /// areas differ.
    pub(crate) fn grid(n: usize) -> Mesh {
        Mesh::grid(n, |i, j| {
            let (x, y) = (i as f64, j as f64);
            [
                x + 0.2 * (1.3 * y + 0.7 * x).sin(),
                y + 0.2 * (0.9 * x).cos(),
                0.0,
            ]
        })
        .unwrap()
    }

    /// The connected components of the active elements by breadth-first search, each sorted.
    pub(crate) fn brute_force_components(active: &[bool], elements: &Elements) -> Vec<Vec<usize>> {
        let mut seen = vec![false; active.len()];
        let mut components = Vec::new();
        for start in 0..active.len() {
            if !active[start] || seen[start] {
                continue;
            }
            let mut members = vec![start];
            seen[start] = true;
            let mut k = 0;
            while k < members.len() {
                for &nb in elements.neighbours(members[k]) {
                    if active[nb] && !seen[nb] {
                        seen[nb] = true;
                        members.push(nb);
                    }
                }
                k += 1;
            }
            members.sort_unstable();
            components.push(members);
        }
        components
    }
}
