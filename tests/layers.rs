//! The service's layers point one way: `cli` | `app` -> `api` | `worker` | `scheduler` ->
//! `domain` | `store` | `plots` -> the model. This test reads every `crate::` path in
//! `service/src` and fails on any arrow the table below does not allow, so a cycle cannot creep in.
//! Within a layer, and in the model, no two files import each other.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Each top-level module and the modules it may use.
const ALLOWED: &[(&str, &[&str])] = &[
    (
        "cli",
        &[
            "app",
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
    // A request's connection may be closed while it waits its turn to send a body.
    (
        "api",
        &[
            "config",
            "connections",
            "domain",
            "plots",
            "store",
            "telemetry",
        ],
    ),
    ("worker", &["domain", "store", "telemetry"]),
    ("scheduler", &["domain", "store", "telemetry"]),
    ("retention", &["domain", "store"]),
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

/// The module path of a source file below its crate's `src` (`stats/query.rs` -> `stats/query`,
/// `montecarlo/mod.rs` -> `montecarlo`, `lib.rs` -> the root, `""`).
fn module_of(relative: &Path) -> String {
    let path = relative.with_extension("");
    let path = path.to_string_lossy().replace('\\', "/");
    match path.as_str() {
        "lib" | "main" => String::new(),
        other => other.strip_suffix("/mod").unwrap_or(other).to_owned(),
    }
}

/// Every path a `use` statement of `source` names, groups expanded (`a::{b, c::d}` -> `a::b`,
/// `a::c::d`); the test module at the end of a file is left out.
fn use_paths(source: &str) -> Vec<String> {
    let source = source.split("#[cfg(test)]").next().unwrap_or_default();
    let mut paths = Vec::new();
    let mut offset = 0;
    for line in source.split_inclusive('\n') {
        let trimmed = line.trim_start();
        let statement = ["pub use ", "pub(crate) use ", "pub(super) use ", "use "]
            .iter()
            .find_map(|keyword| trimmed.strip_prefix(keyword));
        if let Some(rest) = statement {
            let at = offset + line.len() - rest.len();
            let end = source[at..].find(';').map_or(source.len(), |e| at + e);
            expand("", &source[at..end], &mut paths);
        }
        offset += line.len();
    }
    paths
}

fn expand(prefix: &str, tree: &str, out: &mut Vec<String>) {
    let tree: String = tree.chars().filter(|c| !c.is_whitespace()).collect();
    match tree.find('{') {
        Some(open) if tree.ends_with('}') => {
            let head = format!("{prefix}{}", &tree[..open]);
            for item in top_level_items(&tree[open + 1..]) {
                expand(&head, item, out);
            }
        }
        _ => out.push(format!("{prefix}{tree}")),
    }
}

/// The module of `modules` that `path`, used in module `from`, names: its longest prefix that is
/// a module; `None` for a path outside the crate.
fn resolve(from: &str, path: &str, modules: &BTreeSet<String>) -> Option<String> {
    let mut steps = path.split("::").peekable();
    let mut at: Vec<&str> = match steps.peek() {
        Some(&"crate") => Vec::new(),
        Some(&"super") | Some(&"self") => from.split('/').filter(|s| !s.is_empty()).collect(),
        _ => return None,
    };
    while let Some(&step) = steps.peek() {
        match step {
            "crate" | "self" => {}
            "super" => {
                at.pop();
            }
            _ => break,
        }
        steps.next();
    }
    let mut found = None;
    let mut candidate = at.join("/");
    for step in steps {
        candidate = if candidate.is_empty() {
            step.to_owned()
        } else {
            format!("{candidate}/{step}")
        };
        if modules.contains(&candidate) {
            found = Some(candidate.clone());
        }
    }
    found.or_else(|| modules.contains(&at.join("/")).then(|| at.join("/")))
}

/// Pairs of files of `src` that each use the other (a module using its own ancestors, as a child
/// reads its parent's items, is not counted).
fn mutual_imports(src: &Path) -> Vec<String> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let module = |file: &std::path::PathBuf| module_of(file.strip_prefix(src).unwrap());
    let modules: BTreeSet<String> = files.iter().map(module).collect();
    let mut uses: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for file in &files {
        let from = module(file);
        let source = std::fs::read_to_string(file).unwrap();
        for path in use_paths(&source) {
            if let Some(to) = resolve(&from, &path, &modules)
                && to != from
                && !from.starts_with(&format!("{to}/"))
                && !to.is_empty()
            {
                uses.entry(from.clone()).or_default().insert(to);
            }
        }
    }
    let mut pairs = Vec::new();
    for (a, used) in &uses {
        for b in used {
            if a < b && uses.get(b).is_some_and(|back| back.contains(a)) {
                pairs.push(format!("{a} <-> {b}"));
            }
        }
    }
    pairs
}

#[test]
fn no_two_files_import_each_other() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for src in [root.join("src"), root.join("../model/src")] {
        let pairs = mutual_imports(&src);
        assert!(
            pairs.is_empty(),
            "files of {} that import each other:\n{}",
            src.display(),
            pairs.join("\n")
        );
    }
}

#[test]
fn the_pair_finder_resolves_parents_children_and_groups() {
    let modules: BTreeSet<String> = ["", "stats", "stats/query", "stats/summary", "montecarlo"]
        .into_iter()
        .map(str::to_owned)
        .collect();
    let resolve = |from: &str, path: &str| resolve(from, path, &modules);
    assert_eq!(
        resolve("stats/query", "super::summary::Merged").as_deref(),
        Some("stats/summary")
    );
    assert_eq!(
        resolve("stats/query", "super::Accumulator").as_deref(),
        Some("stats")
    );
    assert_eq!(
        resolve("stats", "self::query::x").as_deref(),
        Some("stats/query")
    );
    assert_eq!(
        resolve("stats/query", "crate::montecarlo::Job").as_deref(),
        Some("montecarlo")
    );
    assert_eq!(resolve("stats/query", "serde::Serialize"), None);
    assert_eq!(
        use_paths("use super::{a::{B, C}, d};\nuse crate::e::F;\n#[cfg(test)]\nuse crate::g;"),
        ["super::a::B", "super::a::C", "super::d", "crate::e::F"]
    );
}
