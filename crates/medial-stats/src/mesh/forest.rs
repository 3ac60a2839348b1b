//! Union–find over the elements that are switched on, with each component's extent (area) and
//! mass, and a value per element that can be raised for a whole component at once (the sum of
//! potentials on the element's path to its root).

#[derive(Clone, Debug)]
pub(crate) struct Forest {
    parent: Vec<usize>,
    size: Vec<u32>,
    extent: Vec<f64>,
    mass: Vec<f64>,
    potential: Vec<f64>,
    on: Vec<bool>,
    path: Vec<usize>,
}

impl Forest {
    /// A forest of `n` elements, all off.
    pub(crate) fn new(n: usize) -> Self {
        Self {
            parent: (0..n).collect(),
            size: vec![1; n],
            extent: vec![0.0; n],
            mass: vec![0.0; n],
            potential: vec![0.0; n],
            on: vec![false; n],
            path: Vec::new(),
        }
    }

    /// Every element off again.
    pub(crate) fn clear(&mut self) {
        self.on.fill(false);
    }

    /// Switches `e` on as a component of its own.
    pub(crate) fn switch_on(&mut self, e: usize, extent: f64, mass: f64) {
        self.parent[e] = e;
        self.size[e] = 1;
        self.extent[e] = extent;
        self.mass[e] = mass;
        self.potential[e] = 0.0;
        self.on[e] = true;
    }

    pub(crate) fn is_on(&self, e: usize) -> bool {
        self.on[e]
    }

    /// The root of `e`'s component; compresses the path, keeping every value.
    pub(crate) fn find(&mut self, e: usize) -> usize {
        let mut root = e;
        while self.parent[root] != root {
            self.path.push(root);
            root = self.parent[root];
        }
        // From the node nearest the root down: each node's potential becomes the sum of the
        // potentials from it up to the root (excluded).
        let mut above = 0.0;
        while let Some(node) = self.path.pop() {
            above += self.potential[node];
            self.potential[node] = above;
            self.parent[node] = root;
        }
        root
    }

    /// Joins the components of `a` and `b`; returns the root.
    pub(crate) fn union(&mut self, a: usize, b: usize) -> usize {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra == rb {
            return ra;
        }
        let (root, child) = if self.size[ra] >= self.size[rb] {
            (ra, rb)
        } else {
            (rb, ra)
        };
        self.parent[child] = root;
        self.potential[child] -= self.potential[root];
        self.size[root] += self.size[child];
        self.extent[root] += self.extent[child];
        self.mass[root] += self.mass[child];
        root
    }

    pub(crate) fn is_root(&self, e: usize) -> bool {
        self.parent[e] == e
    }

    /// Extent and mass of the component whose root is `root`.
    pub(crate) fn totals(&self, root: usize) -> (f64, f64) {
        (self.extent[root], self.mass[root])
    }

    /// Adds `v` to the value of every element of the component whose root is `root`.
    pub(crate) fn raise(&mut self, root: usize, v: f64) {
        self.potential[root] += v;
    }

    /// The value of `e`.
    pub(crate) fn value(&mut self, e: usize) -> f64 {
        let root = self.find(e);
        if root == e {
            self.potential[e]
        } else {
            self.potential[e] + self.potential[root]
        }
    }
}
