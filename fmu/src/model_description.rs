//! `modelDescription.xml` and `documentation/index.html`, generated from the variable table.

use std::collections::BTreeSet;
use std::fmt::Write;

use crate::logger::LOG_CATEGORIES;
use crate::variables::{enum_types, Causality, Variable, VariableTable};
use crate::{DEFAULT_STEP_SIZE, DEFAULT_STOP_TIME, MODEL_IDENTIFIER};

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
    // Parameters and inputs have initial="exact" (the default) and a start value. Outputs are
    // initial="calculated" (the default for outputs, written out): the FMU computes them in
    // initialization mode (the zero command of the passive state, whatever the inputs), so they
    // have no start value and are listed in <InitialUnknowns>.
    let calculated = v.causality == Causality::Output;
    if calculated {
        out.push_str(" initial=\"calculated\"");
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
    if !calculated {
        let _ = write!(out, " start=\"{}\"", v.start.xml_text());
    }
    out.push_str("/>\n    </ScalarVariable>\n");
}

/// `generationDateAndTime` (xs:dateTime, UTC). Deterministic when the build asks for it: the
/// reproducible-builds convention `SOURCE_DATE_EPOCH` (seconds since 1970, e.g. the commit time,
/// `git log -1 --format=%ct`) is used when set, so two bundles of the same sources are
/// byte-identical; otherwise the time of the bundling, which is what the attribute means.
pub fn generation_date_and_time() -> String {
    let seconds = std::env::var("SOURCE_DATE_EPOCH")
        .ok()
        .and_then(|text| text.trim().parse::<i64>().ok())
        .unwrap_or_else(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| i64::try_from(d.as_secs()).unwrap_or(i64::MAX))
        });
    utc_date_time(seconds)
}

/// `YYYY-MM-DDThh:mm:ssZ` of `seconds` since 1970-01-01T00:00:00Z (proleptic Gregorian; the
/// days-to-civil conversion of H. Hinnant's date algorithms).
fn utc_date_time(seconds: i64) -> String {
    let days = seconds.div_euclid(86_400);
    let second_of_day = seconds.rem_euclid(86_400);
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let day_of_era = z.rem_euclid(146_097);
    let year_of_era =
        (day_of_era - day_of_era / 1460 + day_of_era / 36_524 - day_of_era / 146_096) / 365;
    let day_of_year = day_of_era - (365 * year_of_era + year_of_era / 4 - year_of_era / 100);
    let mp = (5 * day_of_year + 2) / 153;
    let day = day_of_year - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = year_of_era + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z",
        second_of_day / 3600,
        second_of_day / 60 % 60,
        second_of_day % 60
    )
}

/// The complete `modelDescription.xml` text of `table`'s robot.
pub fn model_description_xml(table: &VariableTable) -> String {
    let mut out = String::new();
    out.push_str("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n");
    let _ = writeln!(
        out,
        "<fmiModelDescription fmiVersion=\"2.0\" modelName=\"{MODEL_IDENTIFIER}\" guid=\"{}\" \
         description=\"{}\" author=\"pfnav\" version=\"{}\" generationTool=\"quad-controller-fmu bundle-fmu\" \
         generationDateAndTime=\"{}\" variableNamingConvention=\"structured\" numberOfEventIndicators=\"0\">",
        table.guid(),
        xml_escape(&format!(
            "Quadruped controller stack (gait FSM, convex MPC on ground reaction forces, leg torque control) \
             as an FMI 2.0 Co-Simulation slave. Frames: world x east, y north, z up; base quaternion (w,x,y,z) \
             rotates body to world; base linear and angular velocities in the world frame. Robot: {} \
             (resources/robot/)."
        ,table.robot_name())),
        env!("CARGO_PKG_VERSION"),
        generation_date_and_time(),
    );
    let _ = writeln!(
        out,
        "  <CoSimulation modelIdentifier=\"{MODEL_IDENTIFIER}\" needsExecutionTool=\"false\" \
         canHandleVariableCommunicationStepSize=\"true\" canInterpolateInputs=\"false\" \
         maxOutputDerivativeOrder=\"0\" canRunAsynchronuously=\"false\" \
         canBeInstantiatedOnlyOncePerProcess=\"false\" canNotUseMemoryManagementFunctions=\"true\" \
         canGetAndSetFMUstate=\"true\" canSerializeFMUstate=\"true\" providesDirectionalDerivative=\"false\"/>"
    );

    let units: BTreeSet<_> = table.rows().iter().filter_map(|v| v.unit).collect();
    out.push_str("  <UnitDefinitions>\n");
    for unit in units {
        let name = xml_escape(unit.name());
        if unit.base_units().is_empty() {
            let _ = writeln!(out, "    <Unit name=\"{name}\"/>");
            continue;
        }
        let _ = write!(out, "    <Unit name=\"{name}\">\n      <BaseUnit");
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
    for v in table.rows() {
        let _ = writeln!(out, "    <!-- index {} -->", v.index());
        scalar_variable(&mut out, v);
    }
    out.push_str("  </ModelVariables>\n");

    // Outputs change only inside fmi2DoStep (the inputs are sampled at the step's start and the
    // outputs hold the command of its last tick), so no output depends directly on an input:
    // dependencies="" (FMI 2.0: an absent attribute would mean "depends on every input", i.e.
    // false algebraic loops). The initial unknowns are the calculated outputs (no continuous
    // states, no calculated parameters); before the first doStep they are the passive zero
    // command, independent of every input and parameter.
    let outputs: Vec<&Variable> = table
        .rows()
        .iter()
        .filter(|v| v.causality == Causality::Output)
        .collect();
    out.push_str("  <ModelStructure>\n    <Outputs>\n");
    for v in &outputs {
        let _ = writeln!(
            out,
            "      <Unknown index=\"{}\" dependencies=\"\"/>",
            v.index()
        );
    }
    out.push_str("    </Outputs>\n    <InitialUnknowns>\n");
    for v in &outputs {
        let _ = writeln!(
            out,
            "      <Unknown index=\"{}\" dependencies=\"\"/>",
            v.index()
        );
    }
    out.push_str("    </InitialUnknowns>\n  </ModelStructure>\n</fmiModelDescription>\n");
    out
}

/// `documentation/index.html`: what the FMU does and the variable table of `table`'s robot.
pub fn documentation_html(table: &VariableTable) -> String {
    let mut out = String::new();
    let _ = write!(
        out,
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{MODEL_IDENTIFIER}</title></head><body>\n\
         <h1>{MODEL_IDENTIFIER} (FMI 2.0 Co-Simulation)</h1>\n<p>Robot: {} (its URDF, robot config and \
         meshes are in resources/robot/).</p>\n<p>{}</p>\n",
        xml_escape(table.robot_name()),
        xml_escape(crate::TIMING_DOC)
    );
    out.push_str(
        "<table border=\"1\"><tr><th>name</th><th>vr</th><th>causality</th><th>variability</th>\
         <th>type</th><th>start</th><th>min</th><th>max</th><th>unit</th><th>description</th></tr>\n",
    );
    for v in table.rows() {
        let _ = writeln!(
            out,
            "<tr><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            xml_escape(&v.name),
            v.value_reference,
            v.causality.xml_name(),
            v.variability.xml_name(),
            v.declared_type
                .map_or_else(|| v.scalar_type().xml_name().to_owned(), |t| format!("Enumeration {t}")),
            if v.causality == Causality::Output { String::new() } else { v.start.xml_text() },
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
    use crate::variables::{by_name, our_table, robot_model, table};

    #[test]
    fn xml_lists_every_variable_and_output_once() {
        let xml = model_description_xml(our_table());
        assert_eq!(xml.matches("<ScalarVariable ").count(), table().len());
        let outputs = table()
            .iter()
            .filter(|v| v.causality == Causality::Output)
            .count();
        // Each output once in <Outputs> and once in <InitialUnknowns>, with no dependencies.
        assert_eq!(xml.matches("<Unknown ").count(), 2 * outputs);
        assert_eq!(xml.matches("dependencies=\"\"/>").count(), 2 * outputs);
        assert!(xml.contains("generationDateAndTime=\""));
        assert!(xml.contains(&format!("guid=\"{}\"", our_table().guid())));
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
        assert!(xml.contains(
            "causality=\"output\" variability=\"discrete\" initial=\"calculated\">\n      <Enumeration declaredType=\"FsmState\"/>"
        ));
        assert!(xml.contains(
            "<Enumeration declaredType=\"ModeRequest\" min=\"0\" max=\"2\" start=\"1\"/>"
        ));
        assert!(xml
            .contains("<Enumeration declaredType=\"GaitKind\" min=\"0\" max=\"1\" start=\"0\"/>"));
    }

    #[test]
    fn generation_time_is_an_xs_date_time_in_utc() {
        assert_eq!(utc_date_time(0), "1970-01-01T00:00:00Z");
        assert_eq!(utc_date_time(951_782_400), "2000-02-29T00:00:00Z");
        assert_eq!(utc_date_time(1_700_000_000), "2023-11-14T22:13:20Z");
        assert_eq!(utc_date_time(4_102_444_799), "2099-12-31T23:59:59Z");
    }

    #[test]
    fn inputs_and_parameters_have_ranges_and_every_variable_a_description() {
        let xml = model_description_xml(our_table());
        for v in table() {
            assert!(!v.description.trim().is_empty(), "{}", v.name);
            let limited = matches!(
                v.binding,
                crate::variables::Binding::JointPosition(_)
                    | crate::variables::Binding::JointVelocity(_)
                    | crate::variables::Binding::JointTorque(_)
            );
            if limited || v.causality == Causality::Parameter {
                assert!(v.min.is_some() && v.max.is_some(), "{}", v.name);
            }
        }
        let model = robot_model();
        let knee = by_name("joint.q[3]").unwrap();
        assert_eq!(
            (knee.min, knee.max),
            (Some(model.lower_limits()[2]), Some(model.upper_limits()[2]))
        );
        assert!(xml.contains("unit=\"rad\" min=\"-2.7\" max=\"-0.5\" start=\""));
        assert!(xml.contains("unit=\"N.m\" min=\"-35.0\" max=\"35.0\"/>"));
    }

    #[test]
    fn escaping() {
        assert_eq!(xml_escape("a<b & \"c\""), "a&lt;b &amp; &quot;c&quot;");
    }
}
