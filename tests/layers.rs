//! ARCHITECTURE.md's layer table, checked against the code: every module of `src/` is in exactly
//! one layer, and no code of a layer names a module of a layer above it (`crate::<module>` in a
//! `use` or a path; comments and `#[cfg(test)]` blocks are not code of the layer: a test module may
//! build its data with `crate::synthetic`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The layers of ARCHITECTURE.md's table, top first: each a list of top-level module names.
fn layers() -> Vec<(String, Vec<String>)> {
    let text = std::fs::read_to_string("ARCHITECTURE.md").expect("ARCHITECTURE.md");
    let section = text.split("## Layers").nth(1).expect("a `## Layers` section").split("\n## ").next().unwrap();
    let mut out = Vec::new();
    for line in section.lines().filter(|l| l.starts_with('|')) {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        if cells.len() < 4 || cells[1] == "layer" || cells[1].starts_with("---") {
            continue;
        }
        let mut modules: Vec<String> = cells[2]
            .split('`')
            .skip(1)
            .step_by(2)
            .filter_map(|p| p.strip_prefix("src/"))
            .map(|p| p.trim_end_matches('/').trim_end_matches(".rs").split('/').next().unwrap().to_string())
            .collect();
        modules.dedup();
        assert!(!modules.is_empty(), "layer row without `src/…` modules: {line}");
        out.push((cells[1].to_string(), modules));
    }
    out
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The code of a file without comments and without the block after each `#[cfg(test)]`.
fn code_of(text: &str) -> String {
    let no_comments: String = text
        .lines()
        .map(|l| match l.find("//") {
            Some(i) if !l[..i].contains('"') => &l[..i],
            _ => l,
        })
        .collect::<Vec<_>>()
        .join("\n");
    let mut out = String::new();
    let mut rest = no_comments.as_str();
    while let Some(i) = rest.find("#[cfg(test)]") {
        out.push_str(&rest[..i]);
        let after = &rest[i..];
        // Skip to the end of the item: a `;` before any `{`, or the matching brace.
        let open = after.find('{');
        let semi = after.find(';');
        let end = match (open, semi) {
            (_, Some(s)) if open.is_none_or(|o| s < o) => s + 1,
            (Some(o), _) => {
                let mut depth = 0usize;
                let mut end = after.len();
                for (j, ch) in after[o..].char_indices() {
                    match ch {
                        '{' => depth += 1,
                        '}' => {
                            depth -= 1;
                            if depth == 0 {
                                end = o + j + 1;
                                break;
                            }
                        }
                        _ => {}
                    }
                }
                end
            }
            _ => after.len(),
        };
        rest = &after[end..];
    }
    out.push_str(rest);
    out
}

/// Top-level modules named by `crate::…` in `code`, including those inside `use crate::{a, b::c}`.
fn named_modules(code: &str) -> Vec<String> {
    let mut out = Vec::new();
    let ident = |s: &str| -> String { s.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect() };
    let mut rest = code;
    while let Some(i) = rest.find("crate::") {
        let after = &rest[i + "crate::".len()..];
        if let Some(group) = after.strip_prefix('{') {
            let end = group.find("};").or_else(|| group.find('}')).unwrap_or(group.len());
            // Top-level names of the group: an identifier at depth 0 after `{` or `,`.
            let mut depth = 0;
            let mut start = true;
            for (j, ch) in group[..end].char_indices() {
                match ch {
                    '{' => depth += 1,
                    '}' => depth -= 1,
                    ',' if depth == 0 => start = true,
                    c if start && depth == 0 && (c.is_ascii_alphabetic() || c == '_') => {
                        out.push(ident(&group[j..]));
                        start = false;
                    }
                    _ => {}
                }
            }
        } else {
            out.push(ident(after));
        }
        rest = after;
    }
    out.retain(|m| !m.is_empty() && m != "self");
    out
}

#[test]
fn every_import_points_down_architecture_md_layers() {
    let layers = layers();
    let mut layer_of: BTreeMap<String, usize> = BTreeMap::new();
    for (i, (name, modules)) in layers.iter().enumerate() {
        for m in modules {
            assert!(layer_of.insert(m.clone(), i).is_none(), "module `{m}` is listed twice (again in `{name}`)");
        }
    }
    let mut files = Vec::new();
    rust_files(Path::new("src"), &mut files);
    files.sort();
    let mut upward = Vec::new();
    for f in &files {
        let rel = f.strip_prefix("src").unwrap();
        let top = rel.components().next().unwrap().as_os_str().to_string_lossy().trim_end_matches(".rs").to_string();
        if top == "lib" {
            continue;
        }
        let Some(&own) = layer_of.get(&top) else {
            panic!("{} belongs to module `{top}`, which ARCHITECTURE.md's layer table does not list", f.display());
        };
        let code = code_of(&std::fs::read_to_string(f).unwrap());
        for m in named_modules(&code) {
            // `crate::Error` / `crate::Result`: lib.rs's re-exports of `error` (bottom).
            let m = if m == "Error" || m == "Result" { "error".to_string() } else { m };
            let Some(&other) = layer_of.get(&m) else {
                panic!("{} names `crate::{m}`, a module ARCHITECTURE.md's layer table does not list", f.display());
            };
            if other < own {
                upward.push(format!(
                    "{} (layer `{}`) uses crate::{m} (layer `{}`, above it)",
                    f.display(),
                    layers[own].0,
                    layers[other].0
                ));
            }
        }
    }
    upward.sort();
    upward.dedup();
    assert!(upward.is_empty(), "imports that run upward:\n{}", upward.join("\n"));
}

#[test]
fn the_checker_sees_grouped_and_nested_imports() {
    let code = "use crate::{error::Result, mesh::{Vec3, TriMesh}, model};\nfn f() { crate::pipeline::x(); }";
    assert_eq!(named_modules(code), ["error", "mesh", "model", "pipeline"]);
    let with_test = "use crate::a;\n#[cfg(test)]\nmod tests { use crate::b; fn g() { {} } }\nuse crate::c; // crate::d";
    assert_eq!(named_modules(&code_of(with_test)), ["a", "c"]);
}

/// Knowledge of a method kind lives in its own files, the registry and the config: nothing else
/// asks "which kind is this?" (`kind() == MethodKind::…`, or the page testing a kind's name).
#[test]
fn no_kind_tests_outside_the_registry_and_the_config() {
    let mut files = Vec::new();
    rust_files(Path::new("src"), &mut files);
    let mut found = Vec::new();
    for f in &files {
        let s = f.to_string_lossy().replace('\\', "/");
        if s.ends_with("pipeline/registry.rs") || s.starts_with("src/config") {
            continue;
        }
        let code = code_of(&std::fs::read_to_string(f).unwrap());
        for pat in ["kind() == MethodKind", "kind() != MethodKind", "MethodKind::Pca =>", "MethodKind::Autoencoder =>"]
        {
            if code.contains(pat) {
                found.push(format!("{s}: `{pat}`"));
            }
        }
    }
    let js = std::fs::read_to_string("src/view/web/app.js").unwrap();
    for name in ["'pca'", "'splocs'", "'region-pca'", "'autoencoder'"] {
        if js.contains(name) {
            found.push(format!("src/view/web/app.js: {name}"));
        }
    }
    assert!(found.is_empty(), "method kinds tested outside the registry and the config:\n{}", found.join("\n"));
}
