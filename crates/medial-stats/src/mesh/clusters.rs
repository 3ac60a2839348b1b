//! Clusters: connected sets of elements whose statistic exceeds a threshold h (on the positive
//! side, and on the negative side too for a two-sided test). A cluster's extent is its area
//! (the sum of its elements' areas, mm²) and its mass the sum of (|statistic| − h) × area.

use std::collections::BTreeMap;

use super::{Elements, Forest, Mesh, Support};
use crate::Tail;

/// A cluster of elements above the threshold.
#[derive(Clone, Debug, PartialEq)]
pub struct Cluster {
    /// 1, 2, …: by decreasing area.
    pub id: usize,
    /// Whether the statistic is above h (true) or below −h (false).
    pub positive: bool,
    /// Elements in the cluster.
    pub elements: usize,
    /// Area, mm².
    pub area: f64,
    /// Σ (|statistic| − h) × area.
    pub mass: f64,
    /// The statistic of largest magnitude in the cluster (signed).
    pub peak: f64,
    /// Where it is.
    pub peak_element: usize,
}

/// The clusters of a statistic map and each element's cluster.
#[derive(Clone, Debug, PartialEq)]
pub struct Clusters {
    /// The id of each element's cluster, 0 outside every cluster.
    pub labels: Vec<usize>,
    /// The clusters, by id.
    pub clusters: Vec<Cluster>,
}

/// The sides a tail looks at: +1 (statistic > h), and −1 (statistic < −h) when two-sided.
fn sides(tail: Tail) -> &'static [f64] {
    match tail {
        Tail::Positive => &[1.0],
        Tail::Both => &[1.0, -1.0],
    }
}

/// Switches on the elements with sign × statistic > threshold and joins neighbours.
fn grow(statistic: &[f64], sign: f64, threshold: f64, elements: &Elements, forest: &mut Forest) {
    forest.clear();
    for (e, &s) in statistic.iter().enumerate() {
        let v = sign * s;
        if v > threshold {
            let area = elements.areas()[e];
            forest.switch_on(e, area, (v - threshold) * area);
        }
    }
    for e in 0..statistic.len() {
        if forest.is_on(e) {
            for &nb in elements.neighbours(e) {
                if nb < e && forest.is_on(nb) {
                    forest.union(e, nb);
                }
            }
        }
    }
}

/// The clusters of `statistic` above `threshold` (NaN is below every threshold).
///
/// ```
/// use medial_stats::{find_clusters, Elements, Mesh, Support, Tail};
///
/// // A strip of four triangles; cells 0, 1 and 3 are above 2.
/// let mesh = Mesh::new(
///     (0..6).map(|i| [f64::from(i / 2), f64::from(i % 2), 0.0]).collect(),
///     vec![[0, 1, 2], [1, 3, 2], [2, 3, 4], [3, 5, 4]],
/// )?;
/// let cells = Elements::new(&mesh, Support::Cells);
/// let found = find_clusters(&[3.0, 2.5, 1.0, 4.0], 2.0, Tail::Positive, &cells);
/// assert_eq!(found.labels, [1, 1, 0, 2]);
/// assert_eq!(found.clusters[0].area, 1.0);
/// assert_eq!(found.clusters[1].peak, 4.0);
/// # Ok::<(), medial_stats::StatsError>(())
/// ```
pub fn find_clusters(
    statistic: &[f64],
    threshold: f64,
    tail: Tail,
    elements: &Elements,
) -> Clusters {
    let mut forest = Forest::new(statistic.len());
    let mut found: Vec<(Cluster, usize, Vec<usize>)> = Vec::new();
    for &sign in sides(tail) {
        grow(statistic, sign, threshold, elements, &mut forest);
        let mut index_of_root = vec![usize::MAX; statistic.len()];
        for (e, &value) in statistic.iter().enumerate() {
            if !forest.is_on(e) {
                continue;
            }
            let root = forest.find(e);
            if index_of_root[root] == usize::MAX {
                index_of_root[root] = found.len();
                let (area, mass) = forest.totals(root);
                let cluster = Cluster {
                    id: 0,
                    positive: sign > 0.0,
                    elements: 0,
                    area,
                    mass,
                    peak: value,
                    peak_element: e,
                };
                found.push((cluster, e, Vec::new()));
            }
            let (cluster, _, members) = &mut found[index_of_root[root]];
            cluster.elements += 1;
            members.push(e);
            if sign * value > sign * cluster.peak {
                cluster.peak = value;
                cluster.peak_element = e;
            }
        }
    }
    found.sort_by(|a, b| b.0.area.total_cmp(&a.0.area).then(a.1.cmp(&b.1)));
    let mut labels = vec![0; statistic.len()];
    let clusters = found
        .into_iter()
        .enumerate()
        .map(|(k, (mut cluster, _, members))| {
            cluster.id = k + 1;
            for e in members {
                labels[e] = k + 1;
            }
            cluster
        })
        .collect();
    Clusters { labels, clusters }
}

/// The outlines of clusters on the mesh, as meshglm's edges file draws them: the triangle edges
/// (pairs of point indices) between a cluster's region and the rest, or on the mesh's border,
/// each with the id of the cluster it outlines (the larger if two clusters meet). A cluster's
/// region is its triangles on cells, and on points the triangles whose three points are in it
/// (a cluster of one point has no outline). Edges across a seam (coincident points) are not
/// borders.
///
/// ```
/// use medial_stats::{cluster_outlines, Mesh, Support};
///
/// // A square of two triangles, the first in cluster 1: its two outer edges and the diagonal.
/// let mesh = Mesh::new(
///     vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
///     vec![[0, 1, 2], [0, 2, 3]],
/// )?;
/// let outline = cluster_outlines(&mesh, Support::Cells, &[1, 0]);
/// assert_eq!(outline, [([0, 1], 1), ([0, 2], 1), ([1, 2], 1)]);
/// # Ok::<(), medial_stats::StatsError>(())
/// ```
pub fn cluster_outlines(
    mesh: &Mesh,
    support: Support,
    labels: &[usize],
) -> Vec<([usize; 2], usize)> {
    let cell_labels: Vec<usize> = match support {
        Support::Cells => labels.to_vec(),
        Support::Points => mesh
            .triangles()
            .iter()
            .map(|t| {
                let l = labels[t[0]];
                if t.iter().all(|&i| labels[i] == l) {
                    l
                } else {
                    0
                }
            })
            .collect(),
    };
    let place = mesh.places();
    // Every edge by its places: the point pair first seen and its triangles' labels.
    let mut edges: BTreeMap<(usize, usize), ([usize; 2], Vec<usize>)> = BTreeMap::new();
    for (t, tri) in mesh.triangles().iter().enumerate() {
        for (a, b) in [(tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])] {
            let key = (place[a].min(place[b]), place[a].max(place[b]));
            edges
                .entry(key)
                .or_insert_with(|| ([a.min(b), a.max(b)], Vec::new()))
                .1
                .push(cell_labels[t]);
        }
    }
    edges
        .into_values()
        .filter_map(|(pair, sides)| {
            let largest = sides.iter().copied().max().unwrap_or(0);
            let border = sides.len() == 1 || sides.iter().any(|&l| l != sides[0]);
            (largest > 0 && border).then_some((pair, largest))
        })
        .collect()
}

/// The largest area and the largest mass of the clusters of `statistic` (0 without clusters):
/// the statistics of cluster inference, for one permutation.
pub(crate) fn largest_extents(
    statistic: &[f64],
    threshold: f64,
    tail: Tail,
    elements: &Elements,
    forest: &mut Forest,
) -> (f64, f64) {
    let (mut area, mut mass) = (0.0_f64, 0.0_f64);
    for &sign in sides(tail) {
        grow(statistic, sign, threshold, elements, forest);
        for e in 0..statistic.len() {
            if forest.is_on(e) && forest.is_root(e) {
                let (a, m) = forest.totals(e);
                area = area.max(a);
                mass = mass.max(m);
            }
        }
    }
    (area, mass)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::tests::{brute_force_components, grid};
    use crate::mesh::Support;
    use proptest::prelude::*;

    #[test]
    fn outlines_follow_the_sheet_across_seams() {
        // A square of two triangles whose diagonal is written twice.
        let mesh = Mesh::new(
            vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            vec![[0, 1, 2], [3, 4, 5]],
        )
        .unwrap();
        let square = [([0, 1], 2), ([1, 2], 2), ([4, 5], 2), ([3, 5], 2)];
        let mut outline = cluster_outlines(&mesh, Support::Cells, &[2, 2]);
        outline.sort_by_key(|e| (e.0[0].min(3), e.0));
        let mut expected = square.to_vec();
        expected.sort_by_key(|e| (e.0[0].min(3), e.0));
        assert_eq!(outline, expected);
        assert_eq!(cluster_outlines(&mesh, Support::Points, &[2; 6]).len(), 4);
        // One point in a cluster outlines no triangle.
        assert!(cluster_outlines(&mesh, Support::Points, &[0, 1, 0, 0, 0, 0]).is_empty());
    }

    proptest! {
        /// Clusters equal the connected components found by breadth-first search, with their
        /// areas and masses summed element by element.
        #[test]
        fn clusters_are_the_components_of_the_supra_threshold_set(
            values in proptest::collection::vec(-3.0..3.0f64, 50),
            threshold in 0.0..2.0f64,
            cells in any::<bool>(),
            two_sided in any::<bool>(),
        ) {
            let support = if cells { Support::Cells } else { Support::Points };
            let elements = Elements::new(&grid(5), support);
            let values = &values[..elements.len()];
            let tail = if two_sided { Tail::Both } else { Tail::Positive };
            let found = find_clusters(values, threshold, tail, &elements);
            let mut expected = Vec::new();
            for &sign in sides(tail) {
                let active: Vec<bool> = values.iter().map(|v| sign * v > threshold).collect();
                for members in brute_force_components(&active, &elements) {
                    let area: f64 = members.iter().map(|&e| elements.areas()[e]).sum();
                    let mass: f64 = members.iter().map(|&e| (sign * values[e] - threshold) * elements.areas()[e]).sum();
                    expected.push((members, area, mass));
                }
            }
            prop_assert_eq!(found.clusters.len(), expected.len());
            for (members, area, mass) in expected {
                let id = found.labels[members[0]];
                prop_assert!(id > 0);
                prop_assert!(members.iter().all(|&e| found.labels[e] == id));
                let cluster = &found.clusters[id - 1];
                prop_assert_eq!(cluster.elements, members.len());
                prop_assert!((cluster.area - area).abs() < 1e-12);
                prop_assert!((cluster.mass - mass).abs() < 1e-12);
                let peak = members.iter().map(|&e| values[e].abs()).fold(0.0, f64::max);
                prop_assert_eq!(cluster.peak.abs(), peak);
            }
            let mut forest = Forest::new(values.len());
            let (largest_area, largest_mass) = largest_extents(values, threshold, tail, &elements, &mut forest);
            let max_area = found.clusters.iter().map(|c| c.area).fold(0.0, f64::max);
            let max_mass = found.clusters.iter().map(|c| c.mass).fold(0.0, f64::max);
            prop_assert_eq!(largest_area, max_area);
            prop_assert!((largest_mass - max_mass).abs() < 1e-12);
        }
    }
}
