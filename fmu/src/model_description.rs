//! `modelDescription.xml` and `documentation/index.html`, generated from the variable table.

use std::collections::BTreeSet;
use std::fmt::Write;

use crate::logger::LOG_CATEGORIES;
use crate::variables::{enum_types, table, Causality, Variable};
use crate::{DEFAULT_STEP_SIZE, DEFAULT_STOP_TIME, GUID, MODEL_IDENTIFIER};

/// Escapes text for XML attribute values and element content.
pub fn xml_escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            _ => out.push(c),
        }
    }
    out
}

fn scalar_variable(out: &mut String, v: &Variable) {
    let _ = write!(
        out,
        "    <ScalarVariable name=\"{}\" valueReference=\"{}\" description=\"{}\" causality=\"{}\" variability=\"{}\"",
        xml_escape(&v.name),
        v.value_reference,
        xml_escape(&v.description),
        v.causality.xml_name(),
        v.variability.xml_name(),
    );
    // Parameters default to initial="exact"; outputs are given exact start values (the zero
    // command before the first doStep), so none of them is an initial unknown.
    if v.causality == Causality::Output {
        out.push_str(" initial=\"exact\"");
    }
    match v.declared_type {
        Some(type_name) => {
            let _ = write!(
                out,
                ">\n      <Enumeration declaredType=\"{}\"",
                xml_escape(type_name)
            );
        }
        None => {
            let _ = write!(out, ">\n      <{}", v.scalar_type().xml_name());
        }
    }
    if let Some(unit) = v.unit {
        let _ = write!(out, " unit=\"{}\"", xml_escape(unit.name()));
    }
    let bound = |b: f64| match v.start {
        crate::variables::Value::Integer(_) => format!("{}", b as i64),
        _ => format!("{b:?}"),
    };
    if let Some(min) = v.min {
        let _ = write!(out, " min=\"{}\"", bound(min));
    }
    if let Some(max) = v.max {
        let _ = write!(out, " max=\"{}\"", bound(max));
    }
    let _ = writeln!(
        out,
        " start=\"{}\"/>\n    </ScalarVariable>",
        v.start.xml_text()
    );
}

/// The complete `modelDescription.xml` text.
pub fn model_description_xml() -> String {
    let mut out = String::new();
    out.push_str("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    let _ = writeln!(
        out,
        "<fmiModelDescription fmiVersion=\"2.0\" modelName=\"{MODEL_IDENTIFIER}\" guid=\"{GUID}\" \
         description=\"{}\" author=\"pfnav\" version=\"{}\" generationTool=\"quad-controller-fmu bundle-fmu\" \
         variableNamingConvention=\"structured\" numberOfEventIndicators=\"0\">",
        xml_escape(
            "Quadruped controller stack (gait FSM, convex MPC on ground reaction forces, leg torque control) \
             as an FMI 2.0 Co-Simulation slave. Frames: world x east, y north, z up; base quaternion (w,x,y,z) \
             rotates body to world; base linear and angular velocities in the world frame."
        ),
        env!("CARGO_PKG_VERSION"),
    );
    let _ = writeln!(
        out,
        "  <CoSimulation modelIdentifier=\"{MODEL_IDENTIFIER}\" needsExecutionTool=\"false\" \
         canHandleVariableCommunicationStepSize=\"true\" canInterpolateInputs=\"false\" \
         maxOutputDerivativeOrder=\"0\" canRunAsynchronuously=\"false\" \
         canBeInstantiatedOnlyOncePerProcess=\"false\" canNotUseMemoryManagementFunctions=\"true\" \
         canGetAndSetFMUstate=\"false\" canSerializeFMUstate=\"false\" providesDirectionalDerivative=\"false\"/>"
    );

    let units: BTreeSet<_> = table().iter().filter_map(|v| v.unit).collect();
    out.push_str("  <UnitDefinitions>\n");
    for unit in units {
        let _ = write!(
            out,
            "    <Unit name=\"{}\">\n      <BaseUnit",
            xml_escape(unit.name())
        );
        for (attribute, exponent) in unit.base_units() {
            let _ = write!(out, " {attribute}=\"{exponent}\"");
        }
        out.push_str("/>\n    </Unit>\n");
    }
    out.push_str("  </UnitDefinitions>\n");

    // Enumeration types (FMI 2.0: their variables are read and written as Integer).
    out.push_str("  <TypeDefinitions>\n");
    for t in enum_types() {
        let _ = writeln!(
            out,
            "    <SimpleType name=\"{}\" description=\"{}\">\n      <Enumeration>",
            xml_escape(t.name),
            xml_escape(t.description)
        );
        for item in &t.items {
            let _ = writeln!(
                out,
                "        <Item name=\"{}\" value=\"{}\" description=\"{}\"/>",
                xml_escape(item.name),
                item.value,
                xml_escape(item.description)
            );
        }
        out.push_str("      </Enumeration>\n    </SimpleType>\n");
    }
    out.push_str("  </TypeDefinitions>\n");

    out.push_str("  <LogCategories>\n");
    for (name, description) in LOG_CATEGORIES {
        let _ = writeln!(
            out,
            "    <Category name=\"{name}\" description=\"{}\"/>",
            xml_escape(description)
        );
    }
    out.push_str("  </LogCategories>\n");

    let _ = writeln!(
        out,
        "  <DefaultExperiment startTime=\"0.0\" stopTime=\"{DEFAULT_STOP_TIME:?}\" stepSize=\"{DEFAULT_STEP_SIZE:?}\"/>"
    );

    out.push_str("  <ModelVariables>\n");
    for v in table() {
        let _ = writeln!(out, "    <!-- index {} -->", v.index());
        scalar_variable(&mut out, v);
    }
    out.push_str("  </ModelVariables>\n");

    out.push_str("  <ModelStructure>\n    <Outputs>\n");
    for v in table().iter().filter(|v| v.causality == Causality::Output) {
        let _ = writeln!(out, "      <Unknown index=\"{}\"/>", v.index());
    }
    out.push_str("    </Outputs>\n  </ModelStructure>\n</fmiModelDescription>\n");
    out
}

/// `documentation/index.html`: what the FMU does and the variable table.
pub fn documentation_html() -> String {
    let mut out = String::new();
    let _ = write!(
        out,
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{MODEL_IDENTIFIER}</title></head><body>\n\
         <h1>{MODEL_IDENTIFIER} (FMI 2.0 Co-Simulation)</h1>\n<p>{}</p>\n",
        xml_escape(crate::TIMING_DOC)
    );
    out.push_str(
        "<table border=\"1\"><tr><th>name</th><th>vr</th><th>causality</th><th>variability</th>\
         <th>type</th><th>start</th><th>min</th><th>max</th><th>unit</th><th>description</th></tr>\n",
    );
    for v in table() {
        let _ = writeln!(
            out,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            xml_escape(&v.name),
            v.value_reference,
            v.causality.xml_name(),
            v.variability.xml_name(),
            v.declared_type
                .map_or_else(|| v.scalar_type().xml_name().to_owned(), |t| format!("Enumeration {t}")),
            v.start.xml_text(),
            v.min.map(|b| format!("{b:?}")).unwrap_or_default(),
            v.max.map(|b| format!("{b:?}")).unwrap_or_default(),
            v.unit.map(|u| u.name()).unwrap_or(""),
            xml_escape(&v.description)
        );
    }
    out.push_str("</table>\n</body></html>\n");
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn xml_lists_every_variable_and_output_once() {
        let xml = model_description_xml();
        assert_eq!(xml.matches("<ScalarVariable ").count(), table().len());
        let outputs = table()
            .iter()
            .filter(|v| v.causality == Causality::Output)
            .count();
        assert_eq!(xml.matches("<Unknown ").count(), outputs);
        assert!(xml.contains(&format!("guid=\"{GUID}\"")));
        assert!(xml.contains("canHandleVariableCommunicationStepSize=\"true\""));
        assert!(!xml.contains("<Derivatives/>"));
        assert!(xml.contains("name=\"joint.q[1]\" valueReference=\"13\""));
        // Every parameter carries its range.
        let parameters = table()
            .iter()
            .filter(|v| v.causality == Causality::Parameter)
            .count();
        let with_range = xml
            .split("<ScalarVariable ")
            .filter(|block| block.contains("causality=\"parameter\""))
            .filter(|block| block.contains(" min=\"") && block.contains(" max=\""))
            .count();
        assert_eq!(with_range, parameters);
        assert!(xml.contains("unit=\"s\" min=\"0.0001\" max=\"0.05\" start=\"0.001\""));
        assert!(xml.contains("<Integer min=\"10\" max=\"40\" start=\"10\"/>"));
        // The FSM states, mode requests and gaits are enumeration types, listed from the
        // controller's own lists.
        assert!(xml.contains("<SimpleType name=\"FsmState\""));
        for (state, name, _) in quad_controller::FsmState::ALL {
            assert!(xml.contains(&format!(
                "<Item name=\"{name}\" value=\"{}\"",
                state.as_code()
            )));
        }
        assert!(xml.contains("<Enumeration declaredType=\"FsmState\" start=\"0\"/>"));
        assert!(xml.contains(
            "<Enumeration declaredType=\"ModeRequest\" min=\"0\" max=\"2\" start=\"1\"/>"
        ));
        assert!(xml
            .contains("<Enumeration declaredType=\"GaitKind\" min=\"0\" max=\"1\" start=\"0\"/>"));
    }

    #[test]
    fn escaping() {
        assert_eq!(xml_escape("a<b & \"c\""), "a&lt;b &amp; &quot;c&quot;");
    }
}
