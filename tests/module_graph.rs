//! The code reads as a map of the data flow: no module imports one that imports it back.
//!
//! Every `.rs` file under `src/` (not `src/bin/`) is mapped to its module path; the
//! crate-internal modules it references (`use crate::a::b`, `crate::a::b::` paths in code,
//! `use super::x`, `super::x::`, `self::x::`, resolved relative to the file's module and
//! its inline modules; comments, doc comments and string literals ignored) are mapped to
//! the deepest existing module file. Then, for every module that has child modules (the
//! crate root included), the graph between its children — each file counted as the child
//! it lies under — must have no cycle. Unit tests (`#[cfg(test)]` items and files) are
//! left out: they may build their fixtures from any module.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

type ModPath = Vec<String>;

/// Top-level cycles that exist today and are too big to untangle in one change, each as
/// the exact set of top-level modules of one strongly connected component. A later change
/// may only shrink this list: any other component (a new cycle, or one of these growing)
/// fails the test.
const ALLOWED_TOP_LEVEL: &[&[&str]] = &[];

/// Module path of a file below `src/`: `lib.rs` is the root, `a/mod.rs` is `a`,
/// `a/b.rs` is `a::b`.
fn module_of(rel: &Path) -> ModPath {
    let mut parts: Vec<String> = rel
        .iter()
        .map(|s| s.to_string_lossy().into_owned())
        .collect();
    let last = parts.pop().unwrap();
    let stem = last.trim_end_matches(".rs");
    if stem != "mod" && stem != "lib" {
        parts.push(stem.to_string());
    }
    parts
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs") {
            out.push(p);
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Ident(String),
    Path, // `::`
    Open,
    Close,
    Comma,
    Semi,
    Star,
    LParen,
    RParen,
    LBrack,
    RBrack,
    Hash,
    Other,
}

/// Tokens of Rust source, with comments, string, byte-string and char literals dropped.
fn tokenize(src: &str) -> Vec<Tok> {
    let c: Vec<char> = src.chars().collect();
    let n = c.len();
    let mut i = 0;
    let mut out = Vec::new();
    while i < n {
        let ch = c[i];
        if ch.is_whitespace() {
            i += 1;
        } else if ch == '/' && i + 1 < n && c[i + 1] == '/' {
            while i < n && c[i] != '\n' {
                i += 1;
            }
        } else if ch == '/' && i + 1 < n && c[i + 1] == '*' {
            let mut depth = 0;
            while i < n {
                if c[i] == '/' && i + 1 < n && c[i + 1] == '*' {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && i + 1 < n && c[i + 1] == '/' {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
        } else if ch == '"' {
            i += 1;
            while i < n && c[i] != '"' {
                if c[i] == '\\' {
                    i += 1;
                }
                i += 1;
            }
            i += 1;
            out.push(Tok::Other);
        } else if (ch == 'r' || ch == 'b')
            && raw_string_start(&c, i).is_some()
            && (i == 0 || !is_ident(c[i - 1]))
        {
            let (hashes, body) = raw_string_start(&c, i).unwrap();
            i = body;
            loop {
                if i >= n {
                    break;
                }
                if c[i] == '"' && (0..hashes).all(|k| i + 1 + k < n && c[i + 1 + k] == '#') {
                    i += 1 + hashes;
                    break;
                }
                i += 1;
            }
            out.push(Tok::Other);
        } else if ch == '\'' {
            // A char literal ('x', '\n', '\u{..}') or a lifetime / label ('a).
            if i + 2 < n && c[i + 1] == '\\' {
                i += 2;
                while i < n && c[i] != '\'' {
                    i += 1;
                }
                i += 1;
            } else if i + 2 < n && c[i + 2] == '\'' {
                i += 3;
            } else {
                i += 1;
                while i < n && is_ident(c[i]) {
                    i += 1;
                }
            }
            out.push(Tok::Other);
        } else if is_ident(ch) {
            let s = i;
            while i < n && is_ident(c[i]) {
                i += 1;
            }
            let word: String = c[s..i].iter().collect();
            if ch.is_ascii_digit() {
                out.push(Tok::Other);
            } else {
                out.push(Tok::Ident(word.trim_start_matches("r#").to_string()));
            }
        } else {
            i += 1;
            out.push(match ch {
                ':' if i < n && c[i] == ':' => {
                    i += 1;
                    Tok::Path
                }
                '{' => Tok::Open,
                '}' => Tok::Close,
                ',' => Tok::Comma,
                ';' => Tok::Semi,
                '*' => Tok::Star,
                '(' => Tok::LParen,
                ')' => Tok::RParen,
                '[' => Tok::LBrack,
                ']' => Tok::RBrack,
                '#' => Tok::Hash,
                _ => Tok::Other,
            });
        }
    }
    out
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// `r"`, `r#"`, `br"`, `b"`: the number of `#`s and the index of the body's first char.
fn raw_string_start(c: &[char], i: usize) -> Option<(usize, usize)> {
    let mut j = i;
    if c[j] == 'b' {
        j += 1;
        if j < c.len() && c[j] == '"' {
            return Some((0, j + 1));
        }
    }
    if j >= c.len() || c[j] != 'r' {
        return None;
    }
    j += 1;
    let mut hashes = 0;
    while j < c.len() && c[j] == '#' {
        hashes += 1;
        j += 1;
    }
    (j < c.len() && c[j] == '"').then_some((hashes, j + 1))
}

/// Drops every `#[cfg(test)]` item (unit tests are no part of the data flow); returns
/// the rest and the names of `#[cfg(test)] mod name;` files declared here.
fn strip_cfg_test(toks: &[Tok]) -> (Vec<Tok>, Vec<String>) {
    let id = |s: &str| Tok::Ident(s.to_string());
    let attr = [
        Tok::Hash,
        Tok::LBrack,
        id("cfg"),
        Tok::LParen,
        id("test"),
        Tok::RParen,
        Tok::RBrack,
    ];
    let mut out = Vec::new();
    let mut test_files = Vec::new();
    let mut i = 0;
    while i < toks.len() {
        if !toks[i..].starts_with(&attr) {
            out.push(toks[i].clone());
            i += 1;
            continue;
        }
        i += attr.len();
        // The item: up to a `;` outside any bracket, or the end of its first `{}` block.
        let start = i;
        let mut depth = 0usize;
        while i < toks.len() {
            let t = &toks[i];
            i += 1;
            match t {
                Tok::Open | Tok::LParen | Tok::LBrack => depth += 1,
                Tok::RParen | Tok::RBrack => depth = depth.saturating_sub(1),
                Tok::Close => {
                    depth = depth.saturating_sub(1);
                    if depth == 0 {
                        break;
                    }
                }
                Tok::Semi if depth == 0 => {
                    if let [Tok::Ident(m), Tok::Ident(name), Tok::Semi] = &toks[start..i] {
                        if m == "mod" {
                            test_files.push(name.clone());
                        }
                    }
                    break;
                }
                _ => {}
            }
        }
    }
    (out, test_files)
}

fn ident(t: Option<&Tok>) -> Option<&str> {
    match t {
        Some(Tok::Ident(s)) => Some(s),
        _ => None,
    }
}

/// Parses a use tree starting at `toks[*i]` with `prefix` already read; pushes every full
/// path. Stops after the tree (at `,`, `}` or `;`, not consumed).
fn use_tree(toks: &[Tok], i: &mut usize, prefix: &[String], out: &mut Vec<ModPath>) {
    let mut path = prefix.to_vec();
    loop {
        match toks.get(*i) {
            Some(Tok::Ident(s)) if s == "as" => {
                *i += 2;
                out.push(path);
                return;
            }
            Some(Tok::Ident(s)) => {
                path.push(s.clone());
                *i += 1;
            }
            Some(Tok::Path) => *i += 1,
            Some(Tok::Star) => {
                *i += 1;
                out.push(path);
                return;
            }
            Some(Tok::Open) => {
                *i += 1;
                loop {
                    match toks.get(*i) {
                        Some(Tok::Close) => {
                            *i += 1;
                            break;
                        }
                        Some(Tok::Comma) => *i += 1,
                        None => return,
                        _ => {
                            let before = *i;
                            use_tree(toks, i, &path, out);
                            if *i == before {
                                *i += 1;
                            }
                        }
                    }
                }
                // `use a::{}` still names `a`.
                out.push(path);
                return;
            }
            _ => {
                out.push(path);
                return;
            }
        }
    }
}

/// Every crate-internal path a file's tokens name, as (module the reference is made
/// from, including inline modules; the path as written).
fn references(toks: &[Tok], file_mod: &ModPath) -> Vec<(ModPath, ModPath)> {
    let mut out = Vec::new();
    // Inline modules: (name, brace depth at which it closes).
    let mut inline: Vec<(String, usize)> = Vec::new();
    let mut depth = 0usize;
    let mut i = 0;
    while i < toks.len() {
        let here = || {
            let mut m = file_mod.clone();
            m.extend(inline.iter().map(|(n, _)| n.clone()));
            m
        };
        match &toks[i] {
            Tok::Open => {
                depth += 1;
                i += 1;
            }
            Tok::Close => {
                if inline.last().is_some_and(|&(_, d)| d == depth) {
                    inline.pop();
                }
                depth = depth.saturating_sub(1);
                i += 1;
            }
            Tok::Ident(k) if k == "mod" => {
                if let (Some(name), Some(Tok::Open)) = (ident(toks.get(i + 1)), toks.get(i + 2)) {
                    inline.push((name.to_string(), depth + 1));
                    depth += 1;
                    i += 3;
                } else {
                    i += 1;
                }
            }
            Tok::Ident(k) if k == "use" => {
                i += 1;
                if toks.get(i) == Some(&Tok::Path) {
                    i += 1;
                }
                let mut paths = Vec::new();
                use_tree(toks, &mut i, &[], &mut paths);
                let m = here();
                for p in paths {
                    if p.first().is_some_and(|s| is_anchor(s)) {
                        out.push((m.clone(), p));
                    }
                }
            }
            Tok::Ident(k) if k == "pub" && toks.get(i + 1) == Some(&Tok::LParen) => {
                // Visibility, `pub(in crate::a)` included: not a reference.
                while i < toks.len() && toks[i] != Tok::RParen {
                    i += 1;
                }
            }
            Tok::Ident(k)
                if is_anchor(k)
                    && toks.get(i + 1) == Some(&Tok::Path)
                    && !(i > 0 && toks[i - 1] == Tok::Path) =>
            {
                let mut p = vec![k.clone()];
                i += 1;
                while toks.get(i) == Some(&Tok::Path) {
                    match ident(toks.get(i + 1)) {
                        Some(s) => {
                            p.push(s.to_string());
                            i += 2;
                        }
                        None => break,
                    }
                }
                out.push((here(), p));
            }
            _ => i += 1,
        }
    }
    out
}

fn is_anchor(s: &str) -> bool {
    matches!(s, "crate" | "super" | "self")
}

/// The module a path names from module `from`, mapped to the deepest existing file.
fn resolve(from: &ModPath, path: &ModPath, files: &BTreeSet<ModPath>) -> Option<ModPath> {
    let mut segs = path.iter().peekable();
    let mut base: ModPath = match segs.next()?.as_str() {
        "crate" => Vec::new(),
        "self" => from.clone(),
        "super" => from[..from.len().checked_sub(1)?].to_vec(),
        _ => return None,
    };
    while segs.peek().is_some_and(|s| *s == "super") {
        segs.next();
        base.pop()?;
    }
    base.extend(segs.cloned());
    (0..=base.len())
        .rev()
        .map(|k| base[..k].to_vec())
        .find(|p| files.contains(p))
}

/// File-level reference graph of the crate: module → modules it references.
fn crate_graph() -> BTreeMap<ModPath, BTreeSet<ModPath>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut paths = Vec::new();
    rust_files(&src, &mut paths);
    let sources: Vec<(ModPath, String)> = paths
        .iter()
        .filter(|p| !p.starts_with(src.join("bin")) && !p.ends_with("main.rs"))
        .map(|p| {
            let rel = p.strip_prefix(&src).unwrap();
            (module_of(rel), std::fs::read_to_string(p).unwrap())
        })
        .collect();
    let files: BTreeSet<ModPath> = sources.iter().map(|(m, _)| m.clone()).collect();
    let stripped: Vec<(ModPath, Vec<Tok>)> = sources
        .iter()
        .map(|(m, text)| (m.clone(), tokenize(text)))
        .collect();
    let mut test_only: BTreeSet<ModPath> = BTreeSet::new();
    let mut code = Vec::new();
    for (m, toks) in stripped {
        let (toks, tests) = strip_cfg_test(&toks);
        test_only.extend(tests.into_iter().map(|t| {
            let mut p = m.clone();
            p.push(t);
            p
        }));
        code.push((m, toks));
    }
    let mut graph = BTreeMap::new();
    for (m, toks) in &code {
        if test_only.iter().any(|t| m.starts_with(t)) {
            continue;
        }
        let edges: &mut BTreeSet<ModPath> = graph.entry(m.clone()).or_default();
        for (from, path) in references(toks, m) {
            if let Some(to) = resolve(&from, &path, &files) {
                if &to != m {
                    edges.insert(to);
                }
            }
        }
    }
    graph
}

/// The graph between the children of `parent`: every file at or below a child counts as
/// that child; files equal to `parent` itself are left out.
fn child_graph(
    graph: &BTreeMap<ModPath, BTreeSet<ModPath>>,
    parent: &ModPath,
) -> BTreeMap<String, BTreeSet<String>> {
    let child = |m: &ModPath| -> Option<String> {
        (m.len() > parent.len() && m.starts_with(parent)).then(|| m[parent.len()].clone())
    };
    let mut g: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (from, tos) in graph {
        let Some(a) = child(from) else { continue };
        let e = g.entry(a.clone()).or_default();
        for to in tos {
            if let Some(b) = child(to) {
                if b != a {
                    e.insert(b);
                }
            }
        }
    }
    g
}

/// Strongly connected components with more than one node (Tarjan).
fn cycles(g: &BTreeMap<String, BTreeSet<String>>) -> Vec<BTreeSet<String>> {
    struct St<'a> {
        g: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on: BTreeSet<&'a str>,
        out: Vec<BTreeSet<String>>,
    }
    fn visit<'a>(s: &mut St<'a>, v: &'a str) {
        let k = s.index.len();
        s.index.insert(v, k);
        s.low.insert(v, k);
        s.stack.push(v);
        s.on.insert(v);
        let g = s.g;
        for w in g.get(v).into_iter().flatten() {
            let w = w.as_str();
            if !s.index.contains_key(w) {
                visit(s, w);
                let lw = s.low[w];
                let lv = s.low.get_mut(v).unwrap();
                *lv = (*lv).min(lw);
            } else if s.on.contains(w) {
                let iw = s.index[w];
                let lv = s.low.get_mut(v).unwrap();
                *lv = (*lv).min(iw);
            }
        }
        if s.low[v] == s.index[v] {
            let mut comp = BTreeSet::new();
            while let Some(w) = s.stack.pop() {
                s.on.remove(w);
                comp.insert(w.to_string());
                if w == v {
                    break;
                }
            }
            if comp.len() > 1 {
                s.out.push(comp);
            }
        }
    }
    let mut s = St {
        g,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on: BTreeSet::new(),
        out: Vec::new(),
    };
    for v in g.keys() {
        if !s.index.contains_key(v.as_str()) {
            visit(&mut s, v);
        }
    }
    s.out
}

/// One cycle through the component, `a → b → … → a`, for the failure message.
fn show_cycle(g: &BTreeMap<String, BTreeSet<String>>, comp: &BTreeSet<String>) -> String {
    let start = comp.iter().next().unwrap().clone();
    // Breadth-first from start's successors back to start, inside the component.
    let mut prev: BTreeMap<String, String> = BTreeMap::new();
    let mut queue = std::collections::VecDeque::new();
    queue.push_back(start.clone());
    'bfs: while let Some(v) = queue.pop_front() {
        for w in g.get(&v).into_iter().flatten() {
            if !comp.contains(w) || prev.contains_key(w) {
                continue;
            }
            prev.insert(w.clone(), v.clone());
            if *w == start {
                break 'bfs;
            }
            queue.push_back(w.clone());
        }
    }
    let mut path = vec![start.clone()];
    let mut v = prev[&start].clone();
    while v != start {
        path.push(v.clone());
        v = prev[&v].clone();
    }
    path.push(start);
    path.reverse();
    path.join(" → ")
}

fn label(parent: &ModPath) -> String {
    if parent.is_empty() {
        "crate".to_string()
    } else {
        parent.join("::")
    }
}

#[test]
fn no_module_imports_one_that_imports_it_back() {
    let graph = crate_graph();
    let parents: BTreeSet<ModPath> = graph
        .keys()
        .filter(|m| !m.is_empty())
        .map(|m| m[..m.len() - 1].to_vec())
        .collect();
    let allowed: Vec<BTreeSet<String>> = ALLOWED_TOP_LEVEL
        .iter()
        .map(|c| c.iter().map(|s| s.to_string()).collect())
        .collect();
    let mut failures = Vec::new();
    for parent in &parents {
        let g = child_graph(&graph, parent);
        for comp in cycles(&g) {
            if parent.is_empty() && allowed.contains(&comp) {
                continue;
            }
            let edges: Vec<String> = comp
                .iter()
                .flat_map(|a| {
                    g[a].iter()
                        .filter(|b| comp.contains(*b))
                        .map(move |b| format!("{a} → {b}"))
                })
                .collect();
            failures.push(format!(
                "{}: cycle {} (component {:?}; edges inside: {})",
                label(parent),
                show_cycle(&g, &comp),
                comp,
                edges.join(", ")
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "module import cycles:\n{}",
        failures.join("\n")
    );
}

#[test]
fn observe_and_integrator_do_not_import_each_other_both_ways() {
    let g = child_graph(&crate_graph(), &Vec::new());
    let uses = |a: &str, b: &str| g.get(a).is_some_and(|e| e.contains(b));
    assert!(
        !(uses("observe", "integrator") && uses("integrator", "observe")),
        "observe ↔ integrator: observe uses integrator = {}, integrator uses observe = {}",
        uses("observe", "integrator"),
        uses("integrator", "observe")
    );
}

/// The checker itself: a cycle through `super` and `crate` paths, in a `use` group and in
/// code, is found; comments, doc comments and strings are not references.
#[test]
fn the_checker_sees_use_groups_super_and_code_paths_but_not_comments() {
    let files: BTreeSet<ModPath> = [
        vec![],
        vec!["a".to_string()],
        vec!["a".to_string(), "x".to_string()],
        vec!["a".to_string(), "y".to_string()],
        vec!["b".to_string()],
    ]
    .into_iter()
    .collect();
    let x: ModPath = vec!["a".into(), "x".into()];
    let src =
        "// use crate::b;\n/// [`crate::b::T`]\n/* crate::b::U */\nlet s = \"crate::b::V\";\n\
               use super::{y::{Y1, Y2 as Z}, self as me};\n\
               mod tests { use super::super::y; }\n\
               fn f() { crate::a::y::g(); let c = 'x'; }\n\
               #[cfg(test)]\nmod t { use crate::b; }\n#[cfg(test)]\nfn h() -> [u8; 1] { crate::b::f() }\n";
    let (toks, _) = strip_cfg_test(&tokenize(src));
    let refs: BTreeSet<ModPath> = references(&toks, &x)
        .into_iter()
        .filter_map(|(from, p)| resolve(&from, &p, &files))
        .collect();
    let want: BTreeSet<ModPath> = [vec!["a".to_string()], vec!["a".into(), "y".into()]]
        .into_iter()
        .collect();
    assert_eq!(refs, want);
    let mut g: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    g.entry("x".into()).or_default().insert("y".into());
    g.entry("y".into()).or_default().insert("x".into());
    let comps = cycles(&g);
    assert_eq!(comps.len(), 1);
    assert_eq!(show_cycle(&g, &comps[0]), "x → y → x");
}

/// The validation pass is split into one file a stage (`src/scene/build/`): the checker
/// maps every stage file to its own child of `scene::build`, sees the stages' imports of
/// one another (so the cycle test above covers them), and the shared value checks
/// (`check`) import no other stage.
#[test]
fn the_checker_covers_every_scene_build_stage() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/scene/build");
    let mut paths = Vec::new();
    rust_files(&dir, &mut paths);
    let stages: BTreeSet<String> = paths
        .iter()
        .filter(|p| !p.ends_with("mod.rs"))
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .collect();
    assert!(stages.len() > 1, "no stage files under {}", dir.display());
    let parent: ModPath = vec!["scene".into(), "build".into()];
    let g = child_graph(&crate_graph(), &parent);
    let seen: BTreeSet<String> = g.keys().cloned().collect();
    assert_eq!(seen, stages, "stage files vs children the checker maps");
    for (stage, uses) in &g {
        if stage != "check" {
            assert!(
                uses.contains("check"),
                "{stage} does not import check: {uses:?}"
            );
        }
    }
    assert!(g["check"].is_empty(), "check imports {:?}", g["check"]);
}
