//! Friction coefficients over pairs of body groups.

/// Symmetric table of Coulomb coefficients μ indexed by the groups of the two bodies.
#[derive(Clone, Debug, PartialEq)]
pub struct FrictionTable {
    default: f64,
    /// Overrides `(group_a, group_b, μ)`, stored with `group_a ≤ group_b`.
    entries: Vec<(u32, u32, f64)>,
}

impl FrictionTable {
    /// A table giving `default` for every pair.
    pub fn new(default: f64) -> Self {
        Self {
            default,
            entries: Vec::new(),
        }
    }

    /// Sets μ for the unordered pair of groups `(a, b)`.
    pub fn set(&mut self, a: u32, b: u32, mu: f64) {
        let key = (a.min(b), a.max(b));
        match self.entries.iter_mut().find(|e| (e.0, e.1) == key) {
            Some(e) => e.2 = mu,
            None => self.entries.push((key.0, key.1, mu)),
        }
    }

    /// μ for the unordered pair of groups `(a, b)`.
    pub fn get(&self, a: u32, b: u32) -> f64 {
        let key = (a.min(b), a.max(b));
        self.entries
            .iter()
            .find(|e| (e.0, e.1) == key)
            .map_or(self.default, |e| e.2)
    }
}
