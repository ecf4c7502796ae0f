//! What loads the output shaft: a hanging mass or a set torque. Below the plant and the
//! paper's constants, which both name loads.

/// What loads the output shaft.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Load {
    /// A mass hanging from a pulley on the output: tau_rot = m g r, inertia m r^2.
    Mass {
        /// Mass, kg.
        mass: f64,
        /// Pulley radius, m.
        radius: f64,
    },
    /// A set torque, N m (a brake or a torque motor).
    Torque(f64),
}

impl Load {
    /// Torque on the output, N m.
    pub fn torque(&self) -> f64 {
        match *self {
            Load::Mass { mass, radius } => mass * crate::G * radius,
            Load::Torque(t) => t,
        }
    }

    /// Inertia the load adds to the output, kg m^2.
    pub fn inertia(&self) -> f64 {
        match *self {
            Load::Mass { mass, radius } => mass * radius * radius,
            Load::Torque(_) => 0.0,
        }
    }
}
