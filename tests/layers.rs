//! The service's layers point one way: `cli` | `app` -> `api` | `worker` | `scheduler` ->
//! `domain` | `store` | `plots` -> the model. This test reads every `crate::` path in
//! `service/src` and fails on any arrow the table below does not allow, so a cycle cannot creep in.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Each top-level module and the modules it may use.
const ALLOWED: &[(&str, &[&str])] = &[
    (
        "cli",
        &[
            "app",
            "bench",
            "compute",
            "config",
            "domain",
            "plots",
            "progress",
            "telemetry",
        ],
    ),
    (
        "app",
        &[
            "api",
            "compute",
            "config",
            "connections",
            "domain",
            "retention",
            "scheduler",
            "store",
            "telemetry",
            "worker",
        ],
    ),
    ("api", &["config", "domain", "plots", "store", "telemetry"]),
    ("worker", &["domain", "store", "telemetry"]),
    ("scheduler", &["domain", "store"]),
    ("retention", &["domain", "store"]),
    ("bench", &["plots", "progress"]),
    ("store", &["domain"]),
    ("domain", &[]),
    ("plots", &[]),
    // The flags name their limits in the domain's terms (a queue bound, schedule limits).
    ("config", &["domain"]),
    ("compute", &[]),
    ("connections", &["telemetry"]),
    ("telemetry", &[]),
    ("progress", &[]),
];

/// The top-level module a source file belongs to (`api/jobs.rs` -> `api`).
fn top_module(relative: &Path) -> String {
    let first = relative.components().next().unwrap().as_os_str();
    first.to_string_lossy().trim_end_matches(".rs").to_owned()
}

/// Every module named right after `crate::`, including inside `use crate::{a, b::c}`.
fn used_modules(source: &str) -> BTreeSet<String> {
    let mut used = BTreeSet::new();
    for (at, _) in source.match_indices("crate::") {
        let rest = &source[at + "crate::".len()..];
        let names: Vec<&str> = match rest.strip_prefix('{') {
            Some(group) => top_level_items(group),
            None => vec![rest],
        };
        for name in names {
            let name: String = name
                .trim()
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if !name.is_empty() {
                used.insert(name);
            }
        }
    }
    used
}

/// The comma-separated items of a `{...}` group (its opening brace already taken), nested groups
/// left inside their item.
fn top_level_items(group: &str) -> Vec<&str> {
    let mut items = Vec::new();
    let (mut depth, mut start) = (0, 0);
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => {
                items.push(&group[start..i]);
                return items;
            }
            '}' => depth -= 1,
            ',' if depth == 0 => {
                items.push(&group[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    items.push(&group[start..]);
    items
}

fn rust_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

#[test]
fn every_arrow_between_service_modules_points_down() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let allowed: BTreeMap<&str, &[&str]> = ALLOWED.iter().copied().collect();
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut wrong = Vec::new();
    for file in &files {
        let relative = file.strip_prefix(&src).unwrap();
        let module = top_module(relative);
        if module == "lib" || module == "main" {
            continue;
        }
        let Some(may_use) = allowed.get(module.as_str()) else {
            wrong.push(format!(
                "{}: module `{module}` has no row in ALLOWED",
                relative.display()
            ));
            continue;
        };
        let source = std::fs::read_to_string(file).unwrap();
        for used in used_modules(&source) {
            if used != module && !may_use.contains(&used.as_str()) {
                wrong.push(format!("{}: `{module}` uses `{used}`", relative.display()));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "arrows against the layers:\n{}",
        wrong.join("\n")
    );
}

#[test]
fn only_start_up_uses_the_api_and_nothing_uses_the_command_line() {
    for (module, may_use) in ALLOWED {
        assert!(!may_use.contains(&"cli"), "`{module}` may use cli");
        assert!(
            *module == "app" || !may_use.contains(&"api"),
            "`{module}` may use api"
        );
    }
}

#[test]
fn the_use_parser_sees_grouped_and_nested_paths() {
    let used = used_modules(
        "use crate::{api::{self, AppState}, store};\nlet x = crate::domain::draw_seed();",
    );
    assert_eq!(
        used.into_iter().collect::<Vec<_>>(),
        ["api", "domain", "store"]
    );
}
