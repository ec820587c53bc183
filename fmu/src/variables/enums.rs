//! The `<TypeDefinitions>` enumerations. They are generated from the controller's own variant
//! lists (`FsmState::ALL`, ...) so that the integer codes an importer reads or writes can never
//! drift from what the controller means by them.

use std::sync::OnceLock;

use quad_controller::{EstimatorKind, FsmState, GaitKind, ModeRequest};

/// An item of an enumeration type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EnumItem {
    /// Item name (the Rust variant name).
    pub name: &'static str,
    /// Integer code, as read and written with `fmi2GetInteger`/`fmi2SetInteger`.
    pub value: i32,
    /// Human description.
    pub description: &'static str,
}

/// An enumeration type of `<TypeDefinitions>` (FMI 2.0 `<SimpleType>` with `<Enumeration>`),
/// generated from the controller's own list of the variants.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EnumType {
    /// Type name, used as `declaredType` by the variables of this type.
    pub name: &'static str,
    /// Human description.
    pub description: &'static str,
    /// Items in code order.
    pub items: Vec<EnumItem>,
}

impl EnumType {
    fn new<T: Copy>(
        name: &'static str,
        description: &'static str,
        all: &[(T, &'static str, &'static str)],
        code: impl Fn(T) -> i32,
    ) -> EnumType {
        let items = all
            .iter()
            .map(|&(variant, name, description)| EnumItem {
                name,
                value: code(variant),
                description,
            })
            .collect();
        EnumType {
            name,
            description,
            items,
        }
    }

    /// `(min, max)` of the item codes.
    pub fn range(&self) -> (f64, f64) {
        let codes = self.items.iter().map(|item| item.value);
        let min = codes.clone().min().unwrap_or(0);
        let max = codes.max().unwrap_or(0);
        (f64::from(min), f64::from(max))
    }
}

/// Name of the enumeration type of `fsm.state`.
pub const FSM_STATE_TYPE: &str = "FsmState";
/// Name of the enumeration type of `cmd.mode`.
pub const MODE_REQUEST_TYPE: &str = "ModeRequest";
/// Name of the enumeration type of `gait.kind`.
pub const GAIT_KIND_TYPE: &str = "GaitKind";
/// Name of the enumeration type of `estimator`.
pub const ESTIMATOR_KIND_TYPE: &str = "EstimatorKind";

/// The enumeration types, built once (order of `<TypeDefinitions>`).
pub fn enum_types() -> &'static [EnumType] {
    static TYPES: OnceLock<Vec<EnumType>> = OnceLock::new();
    TYPES.get_or_init(|| {
        vec![
            EnumType::new(
                FSM_STATE_TYPE,
                "State of the controller's gait state machine",
                &FsmState::ALL,
                FsmState::as_code,
            ),
            EnumType::new(
                MODE_REQUEST_TYPE,
                "Mode requested by the master; the state machine decides the state",
                &ModeRequest::ALL,
                ModeRequest::as_code,
            ),
            EnumType::new(
                GAIT_KIND_TYPE,
                "Gait of the locomotion state",
                &GaitKind::ALL,
                GaitKind::as_code,
            ),
            EnumType::new(
                ESTIMATOR_KIND_TYPE,
                "State the controller runs on",
                &EstimatorKind::ALL,
                EstimatorKind::as_code,
            ),
        ]
    })
}

/// The enumeration type called `name`.
pub fn enum_type(name: &str) -> Option<&'static EnumType> {
    enum_types().iter().find(|t| t.name == name)
}
