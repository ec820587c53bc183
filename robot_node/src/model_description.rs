//! What the node needs from an FMU's `modelDescription.xml`: the GUID, the co-simulation model
//! identifier, every scalar variable's value reference and type, and the codes of the
//! enumeration types. Names are looked up here once, at start, so the control loop only ever
//! handles value references.

use std::collections::HashMap;

use quick_xml::events::{BytesStart, Event};
use quick_xml::Reader;
use thiserror::Error;

/// The FMI base type of a scalar variable (an Enumeration is read and written as Integer).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScalarKind {
    Real,
    Integer,
    Boolean,
    String,
    Enumeration,
}

/// One `<ScalarVariable>`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScalarVariable {
    pub value_reference: u32,
    pub causality: String,
    pub kind: ScalarKind,
    /// `declaredType` of an Enumeration (empty otherwise).
    pub declared_type: String,
    /// The `start` attribute as written (None without one).
    pub start: Option<String>,
}

/// The parts of a model description the node uses.
#[derive(Debug, Clone, Default)]
pub struct ModelDescription {
    pub guid: String,
    pub model_identifier: String,
    variables: HashMap<String, ScalarVariable>,
    /// Enumeration type name → (item name → code).
    enumerations: HashMap<String, HashMap<String, i32>>,
}

#[derive(Debug, Error)]
pub enum ModelDescriptionError {
    #[error("modelDescription.xml is not well-formed XML: {0}")]
    Xml(String),
    #[error("modelDescription.xml: {0}")]
    Invalid(String),
    #[error("the FMU has no variable {name:?}")]
    MissingVariable { name: String },
    #[error("FMU variable {name:?} is {found:?} with causality {causality:?}, expected {expected:?} with causality {expected_causality:?}")]
    WrongVariable {
        name: String,
        found: ScalarKind,
        causality: String,
        expected: ScalarKind,
        expected_causality: String,
    },
    #[error("the FMU's enumeration {enumeration:?} has no item {item:?}")]
    MissingEnumerationItem { enumeration: String, item: String },
}

fn attribute(
    element: &BytesStart<'_>,
    name: &str,
) -> Result<Option<String>, ModelDescriptionError> {
    let found = element
        .try_get_attribute(name)
        .map_err(|e| ModelDescriptionError::Xml(e.to_string()))?;
    found
        .map(|a| {
            a.unescape_value()
                .map(|v| v.into_owned())
                .map_err(|e| ModelDescriptionError::Xml(e.to_string()))
        })
        .transpose()
}

fn required(element: &BytesStart<'_>, name: &str) -> Result<String, ModelDescriptionError> {
    attribute(element, name)?.ok_or_else(|| {
        ModelDescriptionError::Invalid(format!(
            "<{}> without attribute {name}",
            String::from_utf8_lossy(element.name().as_ref())
        ))
    })
}

impl ModelDescription {
    /// Parses the text of a `modelDescription.xml`.
    pub fn parse(xml: &str) -> Result<Self, ModelDescriptionError> {
        let mut reader = Reader::from_str(xml);
        let mut description = Self::default();
        // The variable whose type element (<Real/>, <Integer/>, …) comes next.
        let mut open_variable: Option<(String, u32, String)> = None;
        // The enumeration type whose <Item>s come next.
        let mut open_type: Option<String> = None;
        loop {
            let event = reader
                .read_event()
                .map_err(|e| ModelDescriptionError::Xml(e.to_string()))?;
            let (element, is_start) = match &event {
                Event::Start(e) => (e, true),
                Event::Empty(e) => (e, false),
                Event::End(e) => {
                    match e.name().as_ref() {
                        b"ScalarVariable" => open_variable = None,
                        b"SimpleType" => open_type = None,
                        _ => {}
                    }
                    continue;
                }
                Event::Eof => break,
                _ => continue,
            };
            match element.name().as_ref() {
                b"fmiModelDescription" => description.guid = required(element, "guid")?,
                b"CoSimulation" => {
                    description.model_identifier = required(element, "modelIdentifier")?
                }
                b"ScalarVariable" if is_start => {
                    let name = required(element, "name")?;
                    let reference = required(element, "valueReference")?;
                    let reference = reference.parse::<u32>().map_err(|_| {
                        ModelDescriptionError::Invalid(format!(
                            "variable {name:?} has valueReference {reference:?}"
                        ))
                    })?;
                    let causality =
                        attribute(element, "causality")?.unwrap_or_else(|| "local".to_owned());
                    open_variable = Some((name, reference, causality));
                }
                b"SimpleType" if is_start => open_type = Some(required(element, "name")?),
                b"Item" => {
                    if let Some(type_name) = &open_type {
                        let item = required(element, "name")?;
                        let value = required(element, "value")?;
                        let value = value.parse::<i32>().map_err(|_| {
                            ModelDescriptionError::Invalid(format!(
                                "enumeration {type_name:?} item {item:?} has value {value:?}"
                            ))
                        })?;
                        description
                            .enumerations
                            .entry(type_name.clone())
                            .or_default()
                            .insert(item, value);
                    }
                }
                kind @ (b"Real" | b"Integer" | b"Boolean" | b"String" | b"Enumeration") => {
                    if let Some((name, value_reference, causality)) = open_variable.take() {
                        let (kind, declared_type) = match kind {
                            b"Real" => (ScalarKind::Real, String::new()),
                            b"Integer" => (ScalarKind::Integer, String::new()),
                            b"Boolean" => (ScalarKind::Boolean, String::new()),
                            b"String" => (ScalarKind::String, String::new()),
                            _ => (
                                ScalarKind::Enumeration,
                                attribute(element, "declaredType")?.unwrap_or_default(),
                            ),
                        };
                        let start = attribute(element, "start")?;
                        description.variables.insert(
                            name,
                            ScalarVariable {
                                value_reference,
                                causality,
                                kind,
                                declared_type,
                                start,
                            },
                        );
                    }
                }
                _ => {}
            }
        }
        if description.guid.is_empty() || description.model_identifier.is_empty() {
            return Err(ModelDescriptionError::Invalid(
                "no guid or no <CoSimulation modelIdentifier> (only FMI 2.0 co-simulation FMUs are supported)"
                    .to_owned(),
            ));
        }
        Ok(description)
    }

    /// The variable `name`, checked to be of `kind` (Integer also accepts an Enumeration) and
    /// `causality`.
    pub fn variable(
        &self,
        name: &str,
        kind: ScalarKind,
        causality: &str,
    ) -> Result<&ScalarVariable, ModelDescriptionError> {
        let variable =
            self.variables
                .get(name)
                .ok_or_else(|| ModelDescriptionError::MissingVariable {
                    name: name.to_owned(),
                })?;
        let kind_fits = variable.kind == kind
            || (kind == ScalarKind::Integer && variable.kind == ScalarKind::Enumeration);
        if !kind_fits || variable.causality != causality {
            return Err(ModelDescriptionError::WrongVariable {
                name: name.to_owned(),
                found: variable.kind,
                causality: variable.causality.clone(),
                expected: kind,
                expected_causality: causality.to_owned(),
            });
        }
        Ok(variable)
    }

    /// The code of `item` in the enumeration type of the Enumeration variable `variable`.
    pub fn enumeration_code(
        &self,
        variable: &str,
        item: &str,
    ) -> Result<i32, ModelDescriptionError> {
        let declared = &self
            .variables
            .get(variable)
            .ok_or_else(|| ModelDescriptionError::MissingVariable {
                name: variable.to_owned(),
            })?
            .declared_type;
        self.enumerations
            .get(declared)
            .and_then(|items| items.get(item))
            .copied()
            .ok_or_else(|| ModelDescriptionError::MissingEnumerationItem {
                enumeration: declared.clone(),
                item: item.to_owned(),
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const XML: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="M" guid="{g}">
  <CoSimulation modelIdentifier="M"/>
  <TypeDefinitions>
    <SimpleType name="Mode"><Enumeration>
      <Item name="Off" value="0"/><Item name="On" value="7"/>
    </Enumeration></SimpleType>
  </TypeDefinitions>
  <ModelVariables>
    <ScalarVariable name="x &amp; y" valueReference="3" causality="input"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="mode" valueReference="4" causality="input"><Enumeration declaredType="Mode" start="0"/></ScalarVariable>
    <ScalarVariable name="out" valueReference="5" causality="output"><Real/></ScalarVariable>
  </ModelVariables>
</fmiModelDescription>"#;

    #[test]
    fn variables_and_enumeration_codes_are_found_by_name() {
        let md = ModelDescription::parse(XML).unwrap();
        assert_eq!(md.guid, "{g}");
        assert_eq!(md.model_identifier, "M");
        assert_eq!(
            md.variable("x & y", ScalarKind::Real, "input")
                .unwrap()
                .value_reference,
            3
        );
        assert_eq!(
            md.variable("mode", ScalarKind::Integer, "input")
                .unwrap()
                .value_reference,
            4
        );
        assert_eq!(md.enumeration_code("mode", "On").unwrap(), 7);
        assert_eq!(
            md.variable("mode", ScalarKind::Integer, "input")
                .unwrap()
                .start
                .as_deref(),
            Some("0")
        );
        assert_eq!(
            md.variable("out", ScalarKind::Real, "output")
                .unwrap()
                .start,
            None
        );
        assert!(matches!(
            md.enumeration_code("mode", "Sideways"),
            Err(ModelDescriptionError::MissingEnumerationItem { .. })
        ));
        assert!(matches!(
            md.variable("out", ScalarKind::Real, "input"),
            Err(ModelDescriptionError::WrongVariable { .. })
        ));
        assert!(matches!(
            md.variable("nope", ScalarKind::Real, "input"),
            Err(ModelDescriptionError::MissingVariable { .. })
        ));
    }

    #[test]
    fn broken_descriptions_are_refused_with_the_reason() {
        for (xml, reason) in [
            ("<fmiModelDescription guid=\"g\"><a></b>", "well-formed"),
            ("<fmiModelDescription guid=\"g\"/>", "CoSimulation"),
            (
                "<fmiModelDescription guid=\"g\"><CoSimulation modelIdentifier=\"M\"/><ScalarVariable name=\"a\" valueReference=\"-1\"><Real/></ScalarVariable></fmiModelDescription>",
                "valueReference",
            ),
        ] {
            let error = ModelDescription::parse(xml).unwrap_err().to_string();
            assert!(error.contains(reason), "{xml}: {error}");
        }
    }
}
