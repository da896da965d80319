//! No `use` cycle between the modules of `env/src` (docs/architecture.md#where-world: keep `env/`
//! free of import circles; types two modules share get their own small module below both).
//!
//! Nodes: every top-level module (`geom`, `sim`, `world` = `world/mod.rs`) and every direct
//! submodule (`scenario::schema`, `world::lights`, `map::route`); `crate` is `lib.rs`. Inline
//! modules (`mod tests { .. }`) belong to their file's node.
//!
//! Edges: A → B when code in A names something B defines — in a `use` (at any depth), a path in
//! code or a type, an attribute argument (`#[schemars(transform = crate::..)]`) or a macro
//! argument. Paths are resolved the way rustc does for the forms this crate uses: `crate::`,
//! `super::`, `self::`, child modules, imported names (also a module imported with `self`) and
//! glob imports.
//!
//! Re-exports are aliases, not edges: `pub use child::X` in a parent (or a `pub use` that keeps
//! an item reachable at its old path) only publishes a name, and a path through it is charged to
//! the module that defines the item. So a child that writes `crate::scenario::ResolvedActor`
//! depends on `scenario::resolve`, not on `scenario/mod.rs`: a parent re-exporting its children
//! never makes one child depend on its siblings or on what the parent's own code uses. A module
//! whose own code uses a name it re-exports does depend on the defining module.
//!
//! Two graphs must be acyclic: the one above, and the same graph with each node replaced by its
//! top-level module — so `scenario::* → world::*` together with `world::* → scenario::*` is a
//! cycle even when no two files form one.
//!
//! Limits (both err towards reporting a cycle): a local binding that has the name of an imported
//! item or of a child module counts as a use of it; a glob import sees private names too. Doc
//! comments (links included) are not code and are ignored.

use proc_macro2::{Delimiter, Spacing, TokenStream, TokenTree};
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::Path;

type ModPath = Vec<String>;

#[derive(Debug, Clone)]
struct UseLeaf {
    path: Vec<String>,
    /// The name bound (`None` for a glob).
    name: Option<String>,
}

#[derive(Debug)]
struct Scope {
    file: String,
    node: String,
    defs: BTreeSet<String>,
    children: BTreeSet<String>,
    uses: Vec<UseLeaf>,
    tokens: Vec<TokenTree>,
}

#[derive(Debug, Clone, PartialEq)]
enum Target {
    Module(ModPath),
    /// An item defined in this module.
    Item(ModPath),
}

impl Target {
    fn module(&self) -> &ModPath {
        match self {
            Target::Module(m) | Target::Item(m) => m,
        }
    }
}

/// (from node, to node) → first place seen, "file:line `path`".
type Edges = BTreeMap<(String, String), String>;

#[derive(Debug, Default)]
struct Crate {
    scopes: BTreeMap<ModPath, Scope>,
}

fn is_ident(t: Option<&TokenTree>, s: &str) -> bool {
    matches!(t, Some(TokenTree::Ident(i)) if i == s)
}

fn is_punct(t: Option<&TokenTree>, c: char) -> bool {
    matches!(t, Some(TokenTree::Punct(p)) if p.as_char() == c)
}

/// `::` at `i`.
fn is_sep(toks: &[TokenTree], i: usize) -> bool {
    matches!(toks.get(i), Some(TokenTree::Punct(p)) if p.as_char() == ':' && p.spacing() == Spacing::Joint)
        && is_punct(toks.get(i + 1), ':')
}

fn line(t: &TokenTree) -> usize {
    t.span().start().line
}

/// `pub` or `pub(..)` right before index `i`.
fn preceded_by_pub(toks: &[TokenTree], i: usize) -> bool {
    (i >= 1 && is_ident(toks.get(i - 1), "pub"))
        || (i >= 2
            && matches!(&toks[i - 1], TokenTree::Group(g) if g.delimiter() == Delimiter::Parenthesis)
            && is_ident(toks.get(i - 2), "pub"))
}

/// The leaves of a use tree (the tokens between `use` and `;`).
fn use_leaves(toks: &[TokenTree], prefix: &[String], out: &mut Vec<UseLeaf>) {
    let mut path = prefix.to_vec();
    let mut i = if is_sep(toks, 0) { 2 } else { 0 };
    while i < toks.len() {
        match &toks[i] {
            TokenTree::Ident(id) if id == "as" => {
                if let Some(TokenTree::Ident(alias)) = toks.get(i + 1) {
                    out.push(UseLeaf { path, name: Some(alias.to_string()) });
                }
                return;
            }
            TokenTree::Ident(id) => path.push(id.to_string()),
            TokenTree::Punct(p) if p.as_char() == '*' => {
                out.push(UseLeaf { path, name: None });
                return;
            }
            TokenTree::Group(g) if g.delimiter() == Delimiter::Brace => {
                let inner: Vec<TokenTree> = g.stream().into_iter().collect();
                for sub in inner.split(|t| is_punct(Some(t), ',')) {
                    if !sub.is_empty() {
                        use_leaves(sub, &path, out);
                    }
                }
                return;
            }
            _ => {}
        }
        i += 1;
    }
    let name = match path.as_slice() {
        [.., m, last] if last == "self" => m.clone(),
        [.., last] => last.clone(),
        [] => return,
    };
    out.push(UseLeaf { path, name: Some(name) });
}

/// Index of the `;` ending the statement that starts at `i`.
fn statement_end(toks: &[TokenTree], i: usize) -> usize {
    (i..toks.len()).find(|&k| is_punct(toks.get(k), ';')).unwrap_or(toks.len())
}

impl Crate {
    /// `files`: paths relative to `src/` (`lib.rs`, `map/mod.rs`, `map/route.rs`) and sources.
    fn parse(files: &[(String, String)]) -> Crate {
        let mut c = Crate::default();
        for (rel, text) in files {
            let stem = rel.strip_suffix(".rs").unwrap_or_else(|| panic!("{rel}: not a .rs file"));
            let mut path: ModPath = stem.split('/').map(str::to_string).collect();
            if matches!(path.last().map(String::as_str), Some("mod" | "lib")) {
                path.pop();
            }
            let node =
                if path.is_empty() { "crate".to_string() } else { path[..path.len().min(2)].join("::") };
            let ts: TokenStream =
                text.parse().unwrap_or_else(|e| panic!("env/src/{rel}: does not tokenize: {e:?}"));
            c.register(path, ts.into_iter().collect(), rel, &node);
        }
        c
    }

    /// Item-level names, child modules and `use`s of one module; inline modules recurse.
    fn register(&mut self, path: ModPath, toks: Vec<TokenTree>, file: &str, node: &str) {
        let mut sc = Scope {
            file: file.to_string(),
            node: node.to_string(),
            defs: BTreeSet::new(),
            children: BTreeSet::new(),
            uses: Vec::new(),
            tokens: Vec::new(),
        };
        let mut i = 0;
        while i < toks.len() {
            match &toks[i] {
                TokenTree::Ident(kw) if kw == "mod" => {
                    if let Some(TokenTree::Ident(name)) = toks.get(i + 1) {
                        sc.children.insert(name.to_string());
                        if let Some(TokenTree::Group(g)) = toks.get(i + 2) {
                            if g.delimiter() == Delimiter::Brace {
                                let mut child = path.clone();
                                child.push(name.to_string());
                                self.register(child, g.stream().into_iter().collect(), file, node);
                                i += 3;
                                continue;
                            }
                        }
                    }
                }
                TokenTree::Ident(kw)
                    if ["fn", "struct", "enum", "const", "static", "type", "trait", "union"]
                        .contains(&kw.to_string().as_str()) =>
                {
                    if let Some(TokenTree::Ident(name)) = toks.get(i + 1) {
                        if !["fn", "mut"].contains(&name.to_string().as_str()) {
                            sc.defs.insert(name.to_string());
                        }
                    }
                }
                TokenTree::Ident(kw) if kw == "use" => {
                    let end = statement_end(&toks, i);
                    use_leaves(&toks[i + 1..end], &[], &mut sc.uses);
                }
                _ => {}
            }
            sc.tokens.push(toks[i].clone());
            i += 1;
        }
        self.scopes.insert(path, sc);
    }

    fn lookup(&self, m: &ModPath, name: &str, depth: usize) -> Option<Target> {
        let sc = self.scopes.get(m)?;
        if depth > 32 {
            return None;
        }
        if sc.children.contains(name) {
            let mut p = m.clone();
            p.push(name.to_string());
            return Some(Target::Module(p));
        }
        if sc.defs.contains(name) {
            return Some(Target::Item(m.clone()));
        }
        if let Some(u) = sc.uses.iter().find(|u| u.name.as_deref() == Some(name)) {
            return self.resolve(m, &u.path, depth + 1);
        }
        for u in sc.uses.iter().filter(|u| u.name.is_none()) {
            if let Some(Target::Module(g)) = self.resolve(m, &u.path, depth + 1) {
                if &g != m {
                    if let Some(t) = self.lookup(&g, name, depth + 1) {
                        return Some(t);
                    }
                }
            }
        }
        None
    }

    /// What a path written in module `s` names; `None` for anything outside this crate.
    fn resolve(&self, s: &ModPath, segs: &[String], depth: usize) -> Option<Target> {
        let (first, rest) = segs.split_first()?;
        let mut cur = match first.as_str() {
            "crate" => Vec::new(),
            "super" => {
                let mut p = s.clone();
                p.pop()?;
                p
            }
            "self" => s.clone(),
            name => match self.lookup(s, name, depth + 1)? {
                Target::Module(m) => m,
                item => return Some(item),
            },
        };
        for seg in rest {
            match seg.as_str() {
                "super" => {
                    cur.pop()?;
                }
                "self" => {}
                name => match self.lookup(&cur, name, depth + 1) {
                    Some(Target::Module(m)) => cur = m,
                    Some(item) => return Some(item),
                    // Not a name this check tracks (an enum variant, a method): charge the module.
                    None => return Some(Target::Item(cur)),
                },
            }
        }
        Some(Target::Module(cur))
    }

    /// Node of the file that defines module path `p` (its longest registered prefix).
    fn node_of(&self, p: &ModPath) -> Option<&str> {
        (0..=p.len()).rev().find_map(|k| self.scopes.get(&p[..k]).map(|s| s.node.as_str()))
    }

    fn add_edge(&self, edges: &mut Edges, s: &ModPath, target: Option<Target>, at: &TokenTree, text: &str) {
        let Some(t) = target else { return };
        let (Some(from), Some(to)) = (self.node_of(s), self.node_of(t.module())) else { return };
        if from != to {
            let file = &self.scopes[s].file;
            edges
                .entry((from.to_string(), to.to_string()))
                .or_insert_with(|| format!("env/src/{file}:{} `{text}`", line(at)));
        }
    }

    fn walk(&self, s: &ModPath, toks: &[TokenTree], edges: &mut Edges) {
        let mut i = 0;
        while i < toks.len() {
            match &toks[i] {
                // Inline modules are scopes of their own.
                TokenTree::Ident(kw)
                    if kw == "mod"
                        && matches!(toks.get(i + 2), Some(TokenTree::Group(g)) if g.delimiter() == Delimiter::Brace) =>
                {
                    i += 3;
                    continue;
                }
                // `pub(super)` / `pub(crate)` / `pub(in path)` name a visibility, not a dependency.
                TokenTree::Ident(kw)
                    if kw == "pub"
                        && matches!(toks.get(i + 1), Some(TokenTree::Group(g)) if g.delimiter() == Delimiter::Parenthesis) =>
                {
                    i += 2;
                    continue;
                }
                // `mod child;` declares the tree; it is not a dependency of the parent.
                TokenTree::Ident(kw) if kw == "mod" && is_punct(toks.get(i + 2), ';') => {
                    i += 3;
                    continue;
                }
                TokenTree::Ident(kw) if kw == "use" => {
                    let end = statement_end(toks, i);
                    if !preceded_by_pub(toks, i) {
                        let mut leaves = Vec::new();
                        use_leaves(&toks[i + 1..end], &[], &mut leaves);
                        for u in leaves {
                            let t = self.resolve(s, &u.path, 0);
                            self.add_edge(edges, s, t, &toks[i], &u.path.join("::"));
                        }
                    }
                    i = end + 1;
                    continue;
                }
                TokenTree::Group(g) => {
                    let inner: Vec<TokenTree> = g.stream().into_iter().collect();
                    self.walk(s, &inner, edges);
                }
                TokenTree::Ident(id) => {
                    let after_dot_or_sep = (i >= 1 && is_punct(toks.get(i - 1), '.'))
                        || (i >= 2 && is_punct(toks.get(i - 1), ':') && is_punct(toks.get(i - 2), ':'))
                        || (i >= 1 && is_punct(toks.get(i - 1), '\''));
                    let mut segs = vec![id.to_string()];
                    let mut k = i + 1;
                    while is_sep(toks, k) {
                        match toks.get(k + 2) {
                            Some(TokenTree::Ident(next)) => {
                                segs.push(next.to_string());
                                k += 3;
                            }
                            _ => break,
                        }
                    }
                    if !after_dot_or_sep {
                        let t = self.resolve(s, &segs, 0);
                        self.add_edge(edges, s, t, &toks[i], &segs.join("::"));
                    }
                    i = k;
                    continue;
                }
                _ => {}
            }
            i += 1;
        }
    }

    fn edges(&self) -> Edges {
        let mut edges = Edges::new();
        for (path, sc) in &self.scopes {
            self.walk(path, &sc.tokens, &mut edges);
        }
        edges
    }
}

/// BFS parents of everything reachable from `from`.
fn reach<'e>(adj: &BTreeMap<&'e str, Vec<&'e str>>, from: &'e str) -> BTreeMap<&'e str, &'e str> {
    let mut parent: BTreeMap<&str, &str> = BTreeMap::new();
    let mut q = VecDeque::from([from]);
    while let Some(u) = q.pop_front() {
        for &v in &adj[u] {
            if !parent.contains_key(v) {
                parent.insert(v, u);
                q.push_back(v);
            }
        }
    }
    parent
}

/// Every cycle's description (one per strongly connected component with more than one node).
fn cycles(edges: &Edges) -> Vec<String> {
    let mut adj: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
    for (a, b) in edges.keys() {
        adj.entry(a).or_default().push(b);
        adj.entry(b).or_default();
    }
    let mut seen: BTreeSet<&str> = BTreeSet::new();
    let mut out = Vec::new();
    for &u in adj.keys() {
        if seen.contains(u) {
            continue;
        }
        let parent = reach(&adj, u);
        if !parent.contains_key(u) {
            continue;
        }
        // Shortest cycle through u: walk the BFS parents back from u to u.
        let mut path = vec![u];
        let mut v = parent[u];
        while v != u {
            path.push(v);
            v = parent[v];
        }
        path.push(u);
        path.reverse();
        let component: Vec<&str> =
            parent.keys().copied().filter(|&w| w == u || reach(&adj, w).contains_key(u)).collect();
        seen.extend(component.iter().copied());
        let mut text = format!("cycle among {{{}}}:\n", component.join(", "));
        for w in path.windows(2) {
            text += &format!("  {} -> {}   ({})\n", w[0], w[1], edges[&(w[0].to_string(), w[1].to_string())]);
        }
        out.push(text);
    }
    out
}

/// The same edges between top-level modules.
fn top_level(edges: &Edges) -> Edges {
    let top = |n: &str| n.split("::").next().unwrap_or(n).to_string();
    let mut out = Edges::new();
    for ((a, b), at) in edges {
        let (ta, tb) = (top(a), top(b));
        if ta != tb {
            out.entry((ta, tb)).or_insert_with(|| format!("{a} -> {b}: {at}"));
        }
    }
    out
}

fn read_tree(dir: &Path, rel: &str, out: &mut Vec<(String, String)>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir.join(rel))
        .unwrap_or_else(|e| panic!("{}: {e}", dir.join(rel).display()))
        .map(|e| e.expect("directory entry").path())
        .collect();
    entries.sort();
    for p in entries {
        let name = p.file_name().and_then(|n| n.to_str()).expect("UTF-8 file name").to_string();
        let r = if rel.is_empty() { name.clone() } else { format!("{rel}/{name}") };
        if p.is_dir() {
            read_tree(dir, &r, out);
        } else if name.ends_with(".rs") {
            out.push((r, std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))));
        }
    }
}

fn files(list: &[(&str, &str)]) -> Vec<(String, String)> {
    list.iter().map(|(p, t)| (p.to_string(), t.to_string())).collect()
}

#[test]
fn env_src_has_no_module_cycle() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut list = Vec::new();
    read_tree(&src, "", &mut list);
    let c = Crate::parse(&list);
    assert!(c.scopes.len() > 30, "read only {} modules from {}", c.scopes.len(), src.display());
    let edges = c.edges();
    // The checker sees this crate's real dependencies (guards against it silently seeing none).
    for (a, b) in [("world", "scenario::model"), ("scenario::resolve", "scenario::schema"), ("sim", "world")]
    {
        assert!(edges.contains_key(&(a.to_string(), b.to_string())), "edge {a} -> {b} not found");
    }
    let mut found = cycles(&edges);
    found.extend(cycles(&top_level(&edges)).into_iter().map(|c| format!("top-level {c}")));
    assert!(found.is_empty(), "module dependency cycles in env/src:\n{}", found.join("\n"));
}

/// The binding crate (`python/src`) too: its modules wrap the core crates side by side, and one
/// that needs another's helper is a sign the helper belongs below both (or in the core).
#[test]
fn python_src_has_no_module_cycle() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../python/src");
    let mut list = Vec::new();
    read_tree(&src, "", &mut list);
    let c = Crate::parse(&list);
    assert!(c.scopes.len() > 5, "read only {} modules from {}", c.scopes.len(), src.display());
    let edges = c.edges();
    for (a, b) in [("crate", "env"), ("editor", "env"), ("env", "errors")] {
        assert!(edges.contains_key(&(a.to_string(), b.to_string())), "edge {a} -> {b} not found");
    }
    // The checker labels places as in env/src; here they are in python/src.
    let found = cycles(&edges).join("\n").replace("(env/src/", "(python/src/");
    assert!(found.is_empty(), "module dependency cycles in python/src:\n{found}");
}

/// A parent re-exporting its children is an alias: no child depends on its parent or on the
/// parent's own dependencies.
#[test]
fn checker_charges_reexports_to_the_defining_module() {
    let c = Crate::parse(&files(&[
        ("lib.rs", "pub mod a; pub mod b;"),
        ("a/mod.rs", "pub mod x; pub mod y; pub use x::X; pub use y::*; use crate::b::B; pub fn g(_: B) {}"),
        ("a/x.rs", "#[derive(Debug)] pub struct X;"),
        ("a/y.rs", "use crate::a::X; pub struct Y(pub X);"),
        ("b.rs", "pub struct B;"),
    ]));
    let edges: Vec<(String, String)> = c.edges().into_keys().collect();
    let want = [("a", "b"), ("a::y", "a::x")].map(|(a, b)| (a.to_string(), b.to_string()));
    assert_eq!(edges, want);
    assert!(cycles(&c.edges()).is_empty());
}

#[test]
fn checker_finds_a_cycle_through_glob_super_and_attribute_paths() {
    let c = Crate::parse(&files(&[
        ("lib.rs", "pub mod a;"),
        ("a/mod.rs", "pub mod x; pub mod y; pub use x::X;"),
        ("a/x.rs", "use super::y::*; pub struct X(pub(super) Y);"),
        ("a/y.rs", "#[schemars(transform = crate::a::X::t)] pub struct Y;"),
    ]));
    let found = cycles(&c.edges());
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(found[0].contains("a::x -> a::y") && found[0].contains("a::y -> a::x"), "{}", found[0]);
}

#[test]
fn checker_finds_a_cycle_between_top_level_modules_only() {
    let c = Crate::parse(&files(&[
        ("lib.rs", "pub mod a; pub mod b;"),
        ("a/mod.rs", "pub mod x; pub mod y;"),
        ("a/x.rs", "pub fn f() { crate::b::g() }"),
        ("a/y.rs", "pub(in crate::a) struct Y;"),
        ("b.rs", "pub fn g() {} pub(crate) fn h(_: crate::a::y::Y) {}"),
    ]));
    let edges = c.edges();
    assert!(cycles(&edges).is_empty());
    let top = cycles(&top_level(&edges));
    assert_eq!(top.len(), 1, "{top:?}");
    assert!(top[0].contains("a -> b") && top[0].contains("b -> a"), "{}", top[0]);
}
