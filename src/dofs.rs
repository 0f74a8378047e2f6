//! Unknowns of one step: which grid nodes carry unknowns, their numbering, and Dirichlet constraints.
//!
//! The grid is reset every step, so the map is rebuilt every step from the nodal masses of P2G: only
//! nodes with `m_I` above a relative tolerance carry unknowns. Each active node carries the interleaved
//! unknowns of its [`FieldLayout`], `(du_x, du_y)` or `(du_x, du_y, eta_bar)` in 2D (block size 2 or 3),
//! numbered in node order. Constrained components stay in the system as scaled identity rows `s (x - prescribed)` (so the
//! block structure is kept); their columns are kept in the Jacobian.

/// The unknowns of a grid node: the components of the displacement increment `du` (mm), one per space
/// dimension, followed, for gradient-enhanced materials, by the nodal nonlocal equivalent strain
/// `eta_bar` (-). The one place that knows the block layout, so that code asks "is there an eta_bar, and
/// where" instead of testing the block size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FieldLayout {
    dim: usize,
    eta_bar: bool,
}

impl FieldLayout {
    /// `dim` displacement components per node, and `eta_bar` after them if `eta_bar`.
    pub const fn new(dim: usize, eta_bar: bool) -> Self {
        Self { dim, eta_bar }
    }

    /// Unknowns per node (the block size).
    pub const fn per_node(&self) -> usize {
        self.dim + self.eta_bar as usize
    }

    /// Space dimension: displacement components per node.
    pub const fn dim(&self) -> usize {
        self.dim
    }

    /// The component of `eta_bar` in a node's block, if the model solves for it.
    pub const fn eta_bar(&self) -> Option<usize> {
        if self.eta_bar { Some(self.dim) } else { None }
    }
}

impl Default for FieldLayout {
    /// Plane displacement only.
    fn default() -> Self {
        Self::new(2, false)
    }
}

/// Marker for a node without unknowns.
pub const INACTIVE: u32 = u32::MAX;

/// Node-to-unknown numbering and constraints of one step.
#[derive(Debug, Default, Clone)]
pub struct DofMap {
    layout: FieldLayout,
    /// Active-node index of each grid node, or [`INACTIVE`].
    node_index: Vec<u32>,
    /// Grid node of each active node.
    active: Vec<u32>,
    /// Per unknown: prescribed value if constrained.
    prescribed: Vec<Option<f64>>,
}

impl DofMap {
    /// Numbers the nodes flagged in `active` with the unknowns of `layout` each; nothing constrained yet.
    pub fn rebuild(&mut self, active: &[bool], layout: FieldLayout) {
        self.layout = layout;
        let fields = layout.per_node();
        self.node_index.clear();
        self.active.clear();
        for (node, &a) in active.iter().enumerate() {
            if a {
                self.node_index.push(self.active.len() as u32);
                self.active.push(node as u32);
            } else {
                self.node_index.push(INACTIVE);
            }
        }
        self.prescribed.clear();
        self.prescribed.resize(self.active.len() * fields, None);
    }

    /// Unknowns per node (2: displacement; 3: displacement and eta_bar); not the velocity fields of
    /// contact.
    pub fn unknowns_per_node(&self) -> usize {
        self.layout.per_node()
    }

    /// The unknowns of a node.
    pub fn layout(&self) -> FieldLayout {
        self.layout
    }

    /// Number of active nodes.
    pub fn num_active(&self) -> usize {
        self.active.len()
    }

    /// Number of unknowns.
    pub fn len(&self) -> usize {
        self.prescribed.len()
    }

    /// True if no node carries unknowns.
    pub fn is_empty(&self) -> bool {
        self.prescribed.is_empty()
    }

    /// Active-node index of grid node `node`, if active.
    pub fn active_index(&self, node: usize) -> Option<usize> {
        match self.node_index.get(node) {
            Some(&i) if i != INACTIVE => Some(i as usize),
            _ => None,
        }
    }

    /// Grid node of active node `a`.
    pub fn node(&self, a: usize) -> usize {
        self.active[a] as usize
    }

    /// Active-node indices of all grid nodes ([`INACTIVE`] where inactive).
    pub fn node_indices(&self) -> &[u32] {
        &self.node_index
    }

    /// Grid nodes of the active nodes, in unknown order.
    pub fn active_nodes(&self) -> &[u32] {
        &self.active
    }

    /// Prescribes component `comp` of grid node `node` (ignored if the node is inactive). A later call
    /// for the same component wins.
    pub fn constrain(&mut self, node: usize, comp: usize, value: f64) {
        if let Some(a) = self.active_index(node) {
            let i = a * self.unknowns_per_node() + comp;
            self.prescribed[i] = Some(value);
        }
    }

    /// Prescribed value of unknown `dof`, if constrained.
    pub fn prescribed(&self, dof: usize) -> Option<f64> {
        self.prescribed[dof]
    }

    /// True if unknown `dof` is constrained.
    pub fn is_constrained(&self, dof: usize) -> bool {
        self.prescribed[dof].is_some()
    }

    /// Number of constrained unknowns.
    pub fn num_constrained(&self) -> usize {
        self.prescribed.iter().filter(|p| p.is_some()).count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbering_skips_inactive_nodes_and_keeps_constraints_per_component() {
        let mut d = DofMap::default();
        d.rebuild(&[false, true, true, false, true], FieldLayout::new(2, true));
        assert_eq!(d.num_active(), 3);
        assert_eq!(d.len(), 9);
        assert_eq!(d.active_index(0), None);
        assert_eq!(d.active_index(2), Some(1));
        assert_eq!(d.node(2), 4);
        d.constrain(2, 1, 0.5);
        d.constrain(3, 0, 1.0); // inactive: ignored
        assert_eq!(d.prescribed(4), Some(0.5));
        assert!(!d.is_constrained(3));
        assert_eq!(d.num_constrained(), 1);
        assert_eq!(d.layout().eta_bar(), Some(2));
        assert_eq!(FieldLayout::new(2, false).eta_bar(), None);
        assert_eq!(FieldLayout::new(3, true).per_node(), 4);
    }
}
