//! The guide's configuration reference (docs/guide/src/configuration.md)
//! is generated from the configuration types: every `[section]` struct's
//! fields, their doc comments and their defaults. This test regenerates
//! it and fails when the committed page differs (run with
//! `FSHAPE_BLESS=1` to write it), so the reference cannot drift from the
//! types; it also checks that the fields read from the source are exactly
//! the keys the types serialise.

use fshape_match::{AtlasSection, Config, PrealignSection};

/// The sections, in the order of a file: TOML table, struct, source file.
const SECTIONS: [(&str, &str, &str); 9] = [
    ("model", "ModelSection", "config/sections.rs"),
    ("deformation", "DeformationSection", "config/sections.rs"),
    ("integrator", "IntegratorSection", "config/sections.rs"),
    ("attachment", "AttachmentSection", "config/sections.rs"),
    ("optimizer", "OptimizerSection", "config/sections.rs"),
    ("schedule", "ScheduleSection", "config/schedule.rs"),
    ("[stage]", "StageTable", "config/schedule.rs"),
    ("atlas", "AtlasSection", "config/sections.rs"),
    ("prealign", "PrealignSection", "prealign.rs"),
];

struct Field {
    key: String,
    doc: String,
    kind: String,
    /// A `#[serde(default = "f")]`'s function, named as the value it gives.
    default: Option<String>,
}

/// Rustdoc text as plain Markdown: intra-doc links lose their brackets.
fn plain(text: &str) -> String {
    text.replace("[`", "`").replace("`]", "`")
}

/// The struct's doc comment and its public fields (TOML key, doc, Rust
/// type), read from its source.
fn fields(source: &str, name: &str) -> (String, Vec<Field>) {
    let start = source.find(&format!("pub struct {name} {{")).unwrap_or_else(|| panic!("{name} not found"));
    let before: Vec<&str> = source[..start].lines().rev().skip_while(|l| l.trim_start().starts_with("#[")).collect();
    let doc: Vec<&str> =
        before.iter().take_while(|l| l.trim_start().starts_with("///")).map(|l| l.trim_start()[3..].trim()).collect();
    let struct_doc = plain(&doc.into_iter().rev().collect::<Vec<_>>().join(" "));
    let body = &source[start..start + source[start..].find("\n}").unwrap()];
    let mut out = Vec::new();
    let (mut doc, mut rename, mut default) = (Vec::new(), None, None);
    for line in body.lines().skip(1) {
        let t = line.trim();
        if let Some(d) = t.strip_prefix("///") {
            doc.push(d.trim().to_string());
        } else if let Some(r) = t.strip_prefix("#[serde(rename = \"") {
            rename = Some(r.split('"').next().unwrap().to_string());
        } else if let Some(d) = t.strip_prefix("#[serde(default = \"") {
            default = Some(d.split('"').next().unwrap().to_string());
        } else if let Some(f) = t.strip_prefix("pub ") {
            let (field, kind) = f.split_once(':').unwrap();
            out.push(Field {
                key: rename.take().unwrap_or_else(|| field.trim().to_string()),
                doc: plain(&doc.join(" ")),
                kind: kind.trim().trim_end_matches(',').to_string(),
                default: default.take(),
            });
            doc.clear();
        }
    }
    (struct_doc, out)
}

/// The defaults of the sections that have them, as TOML tables.
fn defaults() -> toml::Table {
    let mut config = Config::new(vec![1.0]);
    config.atlas = Some(AtlasSection::default());
    config.prealign = Some(PrealignSection::default());
    let mut table: toml::Table = toml::from_str(&toml::to_string(&config).unwrap()).unwrap();
    // The widths have no default: `Config::new` takes them.
    table["deformation"].as_table_mut().unwrap().remove("widths");
    table
}

fn reference() -> String {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let defaults = defaults();
    let mut page = String::from(
        "# The configuration file\n\n\
         `fshape match`, `atlas`, `batch` and `shoot` read one TOML file (Python's `match` and `atlas` take the same \
         tables as a dict). Every table and key is listed here, with its default; a key that is not listed is an \
         error, and so is a value out of range, named by its dotted key. Gaussian widths are ours: \
         exp(−u/(2σ²)), u a squared distance (fshapesTk's σ is ours × √2).\n\n\
         This page is generated from the configuration types (their doc comments and defaults) by \
         `FSHAPE_BLESS=1 cargo test -p fshape-match --test matching reference`; the same test fails when it is out of \
         date.\n",
    );
    // The module's explanation of the weights, as its documentation says it.
    let module = std::fs::read_to_string(dir.join("config/mod.rs")).unwrap();
    let docs: Vec<&str> = module.lines().take_while(|l| l.starts_with("//!")).map(|l| l[3..].trim_start()).collect();
    let docs = docs.join("\n");
    let start = docs.find("**Scale-free weights**").unwrap();
    let end = start + docs[start..].find("\n\n").unwrap();
    page.push_str(&format!("\n## Weights\n\n{}\n", plain(&docs[start..end])));
    for (table, name, file) in SECTIONS {
        let source = std::fs::read_to_string(dir.join(file)).unwrap();
        let (doc, fields) = fields(&source, name);
        let section_defaults = defaults.get(table).and_then(|v| v.as_table());
        page.push_str(&format!("\n## `[{table}]`\n\n"));
        let note = doc.trim_start_matches(&format!("`[{table}]`.")).trim().to_string();
        if !note.is_empty() {
            page.push_str(&format!("{note}\n\n"));
        }
        page.push_str("| key | meaning | type | default |\n|---|---|---|---|\n");
        for f in fields {
            let default = match (section_defaults.and_then(|t| t.get(&f.key)), &f.default) {
                (Some(v), _) => format!("`{v}`"),
                (None, Some(d)) => format!("`\"{d}\"`"),
                (None, None) if f.kind.starts_with("Option<") => "none".to_string(),
                (None, None) => "required".to_string(),
            };
            page.push_str(&format!(
                "| `{}` | {} | `{}` | {} |\n",
                f.key,
                f.doc.replace('|', "\\|"),
                f.kind.replace('|', "\\|"),
                default.replace('|', "\\|")
            ));
        }
    }
    page
}

#[test]
fn the_guide_s_configuration_reference_is_generated_from_the_types() {
    let page = reference();
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/guide/src/configuration.md");
    if std::env::var_os("FSHAPE_BLESS").is_some() {
        std::fs::write(&path, &page).unwrap();
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == page,
        "{} is out of date: run FSHAPE_BLESS=1 cargo test -p fshape-match --test matching reference",
        path.display()
    );
}

#[test]
fn the_fields_read_from_the_source_are_the_keys_the_types_write() {
    // A configuration with every optional key set, serialised: its keys
    // per table must be the fields the reference lists.
    let full = Config::parse(
        "[model]\nchannel_weights = [1.0]\n[deformation]\nwidths = [1.0]\nweights = [1.0]\ntolerance = 1e-6\n[integrator]\n\
         [attachment]\nkernel_geom = \"gaussian:1\"\nkernel_signal = \"gaussian:1\"\ntolerance = 1e-6\nmasked_geometry = false\n[optimizer]\n\
         [schedule]\nkernel_geom = [\"gaussian:1\"]\nscheme = [\"rk4\"]\nsteps = [10]\nmax_iterations = [5]\n\
         decrease_tolerance = [1e-3]\ndecrease_window = [5]\nvertices = []\ncoarse_targets = true\n[atlas]\n[prealign]\n",
    )
    .unwrap();
    let written: toml::Table = toml::from_str(&toml::to_string(&full).unwrap()).unwrap();
    // The schedule as stage tables, every key of a stage set (the last
    // stage's vertices are refused only when the plan is checked).
    let staged = Config::parse(
        "[deformation]\nwidths = [1.0]\n[[stage]]\nkernel_geom = \"gaussian:1\"\nscheme = \"rk4\"\nsteps = 10\n\
         max_iterations = 5\ndecrease_tolerance = 1e-3\ndecrease_window = 5\nvertices = 100\ncoarse_target = true\n",
    )
    .unwrap();
    let staged: toml::Table = toml::from_str(&toml::to_string(&staged).unwrap()).unwrap();
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    for (table, name, file) in SECTIONS {
        let source = std::fs::read_to_string(dir.join(file)).unwrap();
        let mut listed: Vec<String> = fields(&source, name).1.into_iter().map(|f| f.key).collect();
        let section = match table.strip_prefix('[').and_then(|t| t.strip_suffix(']')) {
            Some(array) => &staged[array].as_array().unwrap()[0],
            None => &written[table],
        };
        let mut keys: Vec<String> = section.as_table().unwrap().keys().cloned().collect();
        listed.sort();
        keys.sort();
        assert_eq!(listed, keys, "[{table}]");
    }
}
