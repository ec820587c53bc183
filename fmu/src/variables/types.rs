//! The FMI vocabulary of a variable (base type, typed value, causality, variability, unit), kept
//! apart from the table so the XML writer and the C exports can name types without pulling in
//! the table's construction.

/// FMI base type of a variable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScalarType {
    /// `fmi2Real`.
    Real,
    /// `fmi2Integer`.
    Integer,
    /// `fmi2Boolean`.
    Boolean,
}

impl ScalarType {
    /// Element name in `modelDescription.xml`.
    pub fn xml_name(self) -> &'static str {
        match self {
            ScalarType::Real => "Real",
            ScalarType::Integer => "Integer",
            ScalarType::Boolean => "Boolean",
        }
    }
}

/// A typed value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    /// Real.
    Real(f64),
    /// Integer.
    Integer(i32),
    /// Boolean.
    Boolean(bool),
}

impl Value {
    /// Its FMI type.
    pub fn scalar_type(self) -> ScalarType {
        match self {
            Value::Real(_) => ScalarType::Real,
            Value::Integer(_) => ScalarType::Integer,
            Value::Boolean(_) => ScalarType::Boolean,
        }
    }

    /// The value as written in a `start` attribute (round-trips exactly for reals).
    pub fn xml_text(self) -> String {
        match self {
            Value::Real(v) => format!("{v:?}"),
            Value::Integer(v) => v.to_string(),
            Value::Boolean(v) => v.to_string(),
        }
    }
}

/// FMI causality.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Causality {
    /// Set before (fixed) or also during (tunable) the simulation.
    Parameter,
    /// Set by the master before every doStep.
    Input,
    /// Computed by doStep.
    Output,
}

impl Causality {
    /// Attribute value.
    pub fn xml_name(self) -> &'static str {
        match self {
            Causality::Parameter => "parameter",
            Causality::Input => "input",
            Causality::Output => "output",
        }
    }
}

/// FMI variability.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variability {
    /// Parameter that may only change before `fmi2ExitInitializationMode`.
    Fixed,
    /// Parameter that may also change between doSteps.
    Tunable,
    /// Changes only at communication points (all Integer/Boolean signals).
    Discrete,
    /// Real signal.
    Continuous,
}

impl Variability {
    /// Attribute value.
    pub fn xml_name(self) -> &'static str {
        match self {
            Variability::Fixed => "fixed",
            Variability::Tunable => "tunable",
            Variability::Discrete => "discrete",
            Variability::Continuous => "continuous",
        }
    }
}

/// Physical units used by the variables; each is declared in `<UnitDefinitions>`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Unit {
    /// Metre.
    Metre,
    /// Second.
    Second,
    /// Radian.
    Radian,
    /// Metre per second.
    MetrePerSecond,
    /// Radian per second.
    RadianPerSecond,
    /// Newton.
    Newton,
    /// Newton metre.
    NewtonMetre,
    /// Newton metre per radian (joint stiffness).
    NewtonMetrePerRadian,
    /// Newton metre second per radian (joint damping).
    NewtonMetreSecondPerRadian,
    /// Metre per second squared.
    MetrePerSecondSquared,
    /// Gyro white-noise density, rad/s/√Hz.
    RadianPerSecondPerRootHertz,
    /// Gyro bias random-walk density, rad/s²/√Hz.
    RadianPerSecondSquaredPerRootHertz,
    /// Accelerometer noise density, m/s²/√Hz.
    MetrePerSecondSquaredPerRootHertz,
    /// Position random-walk density, m/√s.
    MetrePerRootSecond,
    /// Position random walk per distance travelled, m/√m.
    MetrePerRootMetre,
    /// Square metre (position variance).
    SquareMetre,
    /// Square radian (attitude variance).
    SquareRadian,
}

impl Unit {
    /// Every unit, in declaration order.
    pub const ALL: [Unit; 17] = [
        Unit::Metre,
        Unit::Second,
        Unit::Radian,
        Unit::MetrePerSecond,
        Unit::RadianPerSecond,
        Unit::Newton,
        Unit::NewtonMetre,
        Unit::NewtonMetrePerRadian,
        Unit::NewtonMetreSecondPerRadian,
        Unit::MetrePerSecondSquared,
        Unit::RadianPerSecondPerRootHertz,
        Unit::RadianPerSecondSquaredPerRootHertz,
        Unit::MetrePerSecondSquaredPerRootHertz,
        Unit::MetrePerRootSecond,
        Unit::MetrePerRootMetre,
        Unit::SquareMetre,
        Unit::SquareRadian,
    ];

    /// Unit name (FMI/Modelica notation).
    pub fn name(self) -> &'static str {
        match self {
            Unit::Metre => "m",
            Unit::Second => "s",
            Unit::Radian => "rad",
            Unit::MetrePerSecond => "m/s",
            Unit::RadianPerSecond => "rad/s",
            Unit::Newton => "N",
            Unit::NewtonMetre => "N.m",
            Unit::NewtonMetrePerRadian => "N.m/rad",
            Unit::NewtonMetreSecondPerRadian => "N.m.s/rad",
            Unit::MetrePerSecondSquared => "m/s2",
            Unit::RadianPerSecondPerRootHertz => "rad/s/sqrt(Hz)",
            Unit::RadianPerSecondSquaredPerRootHertz => "rad/s2/sqrt(Hz)",
            Unit::MetrePerSecondSquaredPerRootHertz => "m/s2/sqrt(Hz)",
            Unit::MetrePerRootSecond => "m/sqrt(s)",
            Unit::MetrePerRootMetre => "m/sqrt(m)",
            Unit::SquareMetre => "m2",
            Unit::SquareRadian => "rad2",
        }
    }

    /// SI base-unit exponents as `(attribute, exponent)` for `<BaseUnit>`; empty for the noise
    /// densities, whose half-integer exponents (s^-1/2) FMI's integer exponents cannot state
    /// (they are written without a `<BaseUnit>`).
    pub fn base_units(self) -> &'static [(&'static str, i32)] {
        match self {
            Unit::Metre => &[("m", 1)],
            Unit::Second => &[("s", 1)],
            Unit::Radian => &[("rad", 1)],
            Unit::MetrePerSecond => &[("m", 1), ("s", -1)],
            Unit::RadianPerSecond => &[("s", -1), ("rad", 1)],
            Unit::Newton => &[("kg", 1), ("m", 1), ("s", -2)],
            Unit::NewtonMetre => &[("kg", 1), ("m", 2), ("s", -2)],
            Unit::NewtonMetrePerRadian => &[("kg", 1), ("m", 2), ("s", -2), ("rad", -1)],
            Unit::NewtonMetreSecondPerRadian => &[("kg", 1), ("m", 2), ("s", -1), ("rad", -1)],
            Unit::MetrePerSecondSquared => &[("m", 1), ("s", -2)],
            Unit::SquareMetre => &[("m", 2)],
            Unit::SquareRadian => &[("rad", 2)],
            Unit::RadianPerSecondPerRootHertz
            | Unit::RadianPerSecondSquaredPerRootHertz
            | Unit::MetrePerSecondSquaredPerRootHertz
            | Unit::MetrePerRootSecond
            | Unit::MetrePerRootMetre => &[],
        }
    }
}
