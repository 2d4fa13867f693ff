//! The library names its parameters by their API names (`SolverOptions::bins`); the command
//! line shows its users the flags that set them (`--bins`).

/// API names and the flags that set them, longest first where one name starts another.
const FLAGS: &[(&str, &str)] = &[
    ("SolverOptions::direct_light = false", "--no-direct-light"),
    ("SolverOptions::memory_limit_bytes", "--memory-limit"),
    ("SolverOptions::max_iterations", "--max-iterations"),
    ("SolverOptions::split_depth", "--split-depth"),
    ("SolverOptions::epsilon", "--epsilon"),
    ("SolverOptions::flux_share", "--flux-share"),
    ("SolverOptions::faint_links", "--faint-links"),
    ("SolverOptions::field_ratio", "--field-ratio"),
    ("SolverOptions::bins", "--bins"),
    ("SolverOptions::tol", "--tol"),
    ("SolverKind::Hierarchical", "--solver hierarchical"),
    ("SceneOptions::default_albedo", "--albedo"),
    ("SceneOptions::emit_above", "--emit-above"),
    ("SceneOptions::emission", "--emission"),
    ("VariantOptions::amount", "--amount"),
    ("CameraOptions::width", "--width"),
    ("CameraOptions::height", "--height"),
    ("CameraOptions::fov_deg", "--fov"),
    ("CameraOptions::exposure", "--exposure"),
    ("CameraOptions::eye", "--eye"),
    ("CameraOptions::target", "--target"),
];

/// `text` with every API name of [`FLAGS`] replaced by its flag.
pub fn flagged(text: &str) -> String {
    FLAGS
        .iter()
        .fold(text.to_string(), |t, (api, flag)| t.replace(api, flag))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn api_names_become_flags() {
        assert_eq!(
            flagged("SolverOptions::bins 0 outside 1..=64; raise SolverOptions::max_iterations"),
            "--bins 0 outside 1..=64; raise --max-iterations"
        );
        assert_eq!(flagged("no flag here"), "no flag here");
    }
}
