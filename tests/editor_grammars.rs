//! The TextMate grammars under editors/ (used by VS Code and other editors) are valid JSON,
//! reference only rules they define, and name every built-in, global and RIB request arbor
//! knows, so highlighting keeps up with the language tables.

use std::collections::HashSet;
use std::path::Path;

use serde_json::Value;

fn load(rel: &str) -> Value {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join(rel);
    let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{rel}: {e}"));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{rel} is not JSON: {e}"))
}

/// Every regex of a grammar (match, begin, end), recursively.
fn regexes(v: &Value, out: &mut Vec<String>) {
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                if matches!(k.as_str(), "match" | "begin" | "end") {
                    out.push(x.as_str().unwrap().to_string());
                } else {
                    regexes(x, out);
                }
            }
        }
        Value::Array(a) => a.iter().for_each(|x| regexes(x, out)),
        _ => {}
    }
}

fn includes(v: &Value, out: &mut Vec<String>) {
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                if k == "include" {
                    out.push(x.as_str().unwrap().to_string());
                } else {
                    includes(x, out);
                }
            }
        }
        Value::Array(a) => a.iter().for_each(|x| includes(x, out)),
        _ => {}
    }
}

/// The words of a rule written `\b(a|b|c)\b…`.
fn words(g: &Value, rule: &str) -> HashSet<String> {
    let m = g["repository"][rule]["match"]
        .as_str()
        .unwrap_or_else(|| panic!("no rule {rule}"));
    let open = m.find("\\b(").unwrap() + 3;
    let close = open + m[open..].find(')').unwrap();
    m[open..close].split('|').map(str::to_string).collect()
}

fn check_structure(g: &Value, scope: &str) {
    assert_eq!(g["scopeName"], scope);
    assert!(g["patterns"].as_array().is_some_and(|p| !p.is_empty()));
    let mut inc = Vec::new();
    includes(g, &mut inc);
    for i in inc {
        let key = i.strip_prefix('#').unwrap();
        assert!(
            g["repository"].get(key).is_some(),
            "{scope}: `{i}` is not defined"
        );
    }
    let mut rx = Vec::new();
    regexes(g, &mut rx);
    for r in rx {
        // Parentheses balance outside escapes and classes.
        let (mut depth, mut esc, mut class) = (0i32, false, false);
        for c in r.chars() {
            match c {
                _ if esc => esc = false,
                '\\' => esc = true,
                '[' if !class => class = true,
                ']' if class => class = false,
                '(' if !class => depth += 1,
                ')' if !class => depth -= 1,
                _ => {}
            }
            assert!(depth >= 0, "{scope}: unbalanced `{r}`");
        }
        assert_eq!(depth, 0, "{scope}: unbalanced `{r}`");
    }
}

#[test]
fn shading_language_grammar_covers_builtins_globals_and_keywords() {
    let g = load("editors/textmate/rsl.tmLanguage.json");
    check_structure(&g, "source.rsl");
    let mut known = words(&g, "builtins");
    known.extend(words(&g, "shader-types"));
    known.extend(words(&g, "control"));
    for s in arbor::sl::builtins::SIGS {
        assert!(
            known.contains(s.name),
            "built-in `{}` is not highlighted",
            s.name
        );
    }
    for s in arbor::sl::builtins::SPECIAL {
        assert!(known.contains(*s), "built-in `{s}` is not highlighted");
    }
    let globals = words(&g, "globals");
    for (name, ..) in arbor::sl::lower::GLOBALS {
        assert!(
            globals.contains(*name),
            "global `{name}` is not highlighted"
        );
    }
    let types = words(&g, "types");
    for t in [
        "float", "string", "color", "point", "vector", "normal", "matrix", "void",
    ] {
        assert!(types.contains(t), "{t}");
    }
    let control = words(&g, "control");
    for k in [
        "if",
        "else",
        "for",
        "while",
        "return",
        "illuminance",
        "illuminate",
        "solar",
    ] {
        assert!(control.contains(k), "{k}");
    }
    let modifiers = words(&g, "modifiers");
    for k in ["uniform", "varying", "output", "extern"] {
        assert!(modifiers.contains(k), "{k}");
    }
}

#[test]
fn rib_grammar_covers_every_request() {
    let g = load("editors/textmate/rib.tmLanguage.json");
    check_structure(&g, "source.rib");
    let reqs = words(&g, "requests");
    for n in arbor::scene::table::names() {
        assert!(reqs.contains(n), "request `{n}` is not highlighted");
    }
}

#[test]
fn vscode_extension_points_at_the_grammars() {
    let p = load("editors/vscode/package.json");
    let base = Path::new(env!("CARGO_MANIFEST_DIR")).join("editors/vscode");
    let grammars = p["contributes"]["grammars"].as_array().unwrap();
    assert_eq!(grammars.len(), 2);
    for gr in grammars {
        let path = base.join(gr["path"].as_str().unwrap());
        assert!(path.is_file(), "{}", path.display());
    }
    for l in p["contributes"]["languages"].as_array().unwrap() {
        let c = base.join(l["configuration"].as_str().unwrap());
        let text = std::fs::read_to_string(&c).unwrap();
        serde_json::from_str::<Value>(&text).unwrap();
    }
}
