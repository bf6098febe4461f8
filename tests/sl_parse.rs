//! Shading-language parser tests: precedence, every statement form, the RISpec standard
//! shaders, classic shaders, rendered syntax errors, robustness and speed.

use std::fmt::Write as _;

use arbor::diag::{Diagnostics, SourceMap, Span};
use arbor::sl::ast::*;
use arbor::sl::parse::parse;

/// Parses `text` registered as `name`; returns the tree and the rendered diagnostics.
fn parse_named(name: &str, text: &str) -> (Option<SourceFile>, String, Diagnostics) {
    let sources = SourceMap::new();
    let file = sources.add(name, text);
    let diags = Diagnostics::new();
    let tree = parse(text, &|s, e| Span::new(file, s, e), &diags);
    let rendered = diags.render_plain(&sources);
    (tree, rendered, diags)
}

/// Parses text that must be free of errors.
fn ok(text: &str) -> SourceFile {
    let (tree, rendered, diags) = parse_named("test.sl", text);
    assert!(!diags.has_errors(), "unexpected errors:\n{rendered}");
    tree.expect("a tree")
}

/// Parses one expression (as the initialiser of a local) and prints it as an s-expression.
fn e(src: &str) -> String {
    let text = format!("surface t() {{ float __v = {src}; }}");
    let file = ok(&text);
    let Item::Shader(sh) = &file.items[0] else {
        panic!("no shader")
    };
    let StmtKind::VarDecl { vars, .. } = &sh.body.stmts[0].kind else {
        panic!("no declaration")
    };
    sexpr(vars[0].init.as_ref().expect("initialiser"))
}

fn sexpr(x: &Expr) -> String {
    let mut s = String::new();
    write_expr(&mut s, x);
    s
}

fn write_expr(o: &mut String, x: &Expr) {
    match &x.kind {
        ExprKind::Float(v) => write!(o, "{v}").unwrap(),
        ExprKind::Str(v) => write!(o, "{v:?}").unwrap(),
        ExprKind::Ident(n) => o.push_str(n),
        ExprKind::Index { base, index } => {
            o.push_str("(idx ");
            write_expr(o, base);
            o.push(' ');
            write_expr(o, index);
            o.push(')');
        }
        ExprKind::Call { name, args, .. } => {
            write!(o, "({name}").unwrap();
            for a in args {
                o.push(' ');
                write_expr(o, a);
            }
            o.push(')');
        }
        ExprKind::Tuple(items) | ExprKind::ArrayLit(items) => {
            o.push_str(if matches!(x.kind, ExprKind::Tuple(_)) {
                "(tuple"
            } else {
                "(array"
            });
            for a in items {
                o.push(' ');
                write_expr(o, a);
            }
            o.push(')');
        }
        ExprKind::Cast { ty, space, expr } => {
            write!(o, "(cast {}", ty.name()).unwrap();
            if let Some(sp) = space {
                write!(o, " {sp:?}").unwrap();
            }
            o.push(' ');
            write_expr(o, expr);
            o.push(')');
        }
        ExprKind::Unary { op, expr } => {
            let s = match op {
                UnOp::Neg => "neg",
                UnOp::Not => "not",
                UnOp::Plus => "pos",
            };
            write!(o, "({s} ").unwrap();
            write_expr(o, expr);
            o.push(')');
        }
        ExprKind::Binary { op, lhs, rhs } => {
            write!(o, "({} ", op.symbol()).unwrap();
            write_expr(o, lhs);
            o.push(' ');
            write_expr(o, rhs);
            o.push(')');
        }
        ExprKind::Ternary {
            cond,
            then,
            otherwise,
        } => {
            o.push_str("(? ");
            write_expr(o, cond);
            o.push(' ');
            write_expr(o, then);
            o.push(' ');
            write_expr(o, otherwise);
            o.push(')');
        }
        ExprKind::Assign { op, target, value } => {
            let s = match op {
                AssignOp::Set => "=",
                AssignOp::Add => "+=",
                AssignOp::Sub => "-=",
                AssignOp::Mul => "*=",
                AssignOp::Div => "/=",
            };
            write!(o, "({s} ").unwrap();
            write_expr(o, target);
            o.push(' ');
            write_expr(o, value);
            o.push(')');
        }
    }
}

fn type_str(t: &TypeSpec) -> String {
    match t.detail {
        Some(Detail::Uniform) => format!("uniform {}", t.base.name()),
        Some(Detail::Varying) => format!("varying {}", t.base.name()),
        None => t.base.name().to_string(),
    }
}

fn array_str(a: &Option<ArraySpec>) -> String {
    match a {
        None => String::new(),
        Some(ArraySpec::Unsized) => "[]".into(),
        Some(ArraySpec::Sized(n)) => format!("[{n}]"),
    }
}

/// A compact, indented outline of a whole file (for reviewable snapshots).
fn outline(f: &SourceFile) -> String {
    let mut o = String::new();
    for item in &f.items {
        match item {
            Item::Shader(s) => {
                writeln!(o, "{} {}", s.kind.name(), s.name).unwrap();
                formals(&mut o, &s.params, 1);
                block(&mut o, &s.body, 1);
            }
            Item::Function(fd) => func(&mut o, fd, 0),
        }
    }
    o
}

fn func(o: &mut String, f: &FuncDef, d: usize) {
    writeln!(
        o,
        "{}function {} {}",
        "  ".repeat(d),
        type_str(&f.ret),
        f.name
    )
    .unwrap();
    formals(o, &f.params, d + 1);
    block(o, &f.body, d + 1);
}

fn formals(o: &mut String, ps: &[Formal], d: usize) {
    for p in ps {
        write!(
            o,
            "{}param {}{} {}{}",
            "  ".repeat(d),
            if p.output { "output " } else { "" },
            type_str(&p.ty),
            p.name,
            array_str(&p.array)
        )
        .unwrap();
        if let Some(x) = &p.default {
            write!(o, " = {}", sexpr(x)).unwrap();
        }
        o.push('\n');
    }
}

fn block(o: &mut String, b: &Block, d: usize) {
    for s in &b.stmts {
        stmt(o, s, d);
    }
}

fn stmt(o: &mut String, s: &Stmt, d: usize) {
    let ind = "  ".repeat(d);
    match &s.kind {
        StmtKind::VarDecl {
            is_extern,
            output,
            ty,
            vars,
        } => {
            write!(
                o,
                "{ind}decl {}{}{}",
                if *is_extern { "extern " } else { "" },
                if *output { "output " } else { "" },
                type_str(ty)
            )
            .unwrap();
            for v in vars {
                write!(o, " {}{}", v.name, array_str(&v.array)).unwrap();
                if let Some(x) = &v.init {
                    write!(o, "={}", sexpr(x)).unwrap();
                }
            }
            o.push('\n');
        }
        StmtKind::Function(f) => func(o, f, d),
        StmtKind::Expr(x) => writeln!(o, "{ind}{}", sexpr(x)).unwrap(),
        StmtKind::Block(b) => {
            writeln!(o, "{ind}block").unwrap();
            block(o, b, d + 1);
        }
        StmtKind::If {
            cond,
            then,
            otherwise,
        } => {
            writeln!(o, "{ind}if {}", sexpr(cond)).unwrap();
            stmt(o, then, d + 1);
            if let Some(e) = otherwise {
                writeln!(o, "{ind}else").unwrap();
                stmt(o, e, d + 1);
            }
        }
        StmtKind::While { cond, body } => {
            writeln!(o, "{ind}while {}", sexpr(cond)).unwrap();
            stmt(o, body, d + 1);
        }
        StmtKind::For {
            init,
            cond,
            step,
            body,
        } => {
            let f = |x: &Option<Expr>| x.as_ref().map(sexpr).unwrap_or_default();
            writeln!(o, "{ind}for {}; {}; {}", f(init), f(cond), f(step)).unwrap();
            stmt(o, body, d + 1);
        }
        StmtKind::Break(n) => writeln!(o, "{ind}break {n}").unwrap(),
        StmtKind::Continue(n) => writeln!(o, "{ind}continue {n}").unwrap(),
        StmtKind::Return(x) => writeln!(
            o,
            "{ind}return {}",
            x.as_ref().map(sexpr).unwrap_or_default()
        )
        .unwrap(),
        StmtKind::Illuminance { args, body }
        | StmtKind::Illuminate { args, body }
        | StmtKind::Solar { args, body } => {
            let name = match &s.kind {
                StmtKind::Illuminance { .. } => "illuminance",
                StmtKind::Illuminate { .. } => "illuminate",
                _ => "solar",
            };
            let a: Vec<String> = args.iter().map(sexpr).collect();
            writeln!(o, "{ind}{name}({})", a.join(", ")).unwrap();
            stmt(o, body, d + 1);
        }
        StmtKind::Gather {
            args,
            body,
            otherwise,
        } => {
            let a: Vec<String> = args.iter().map(sexpr).collect();
            writeln!(o, "{ind}gather({})", a.join(", ")).unwrap();
            stmt(o, body, d + 1);
            if let Some(e) = otherwise {
                writeln!(o, "{ind}else").unwrap();
                stmt(o, e, d + 1);
            }
        }
        StmtKind::Empty => writeln!(o, "{ind};").unwrap(),
    }
}

fn input(name: &str) -> String {
    let path = format!("{}/tests/sl_inputs/{name}.sl", env!("CARGO_MANIFEST_DIR"));
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"))
}

// ------------------------------------------------------------------ precedence

#[test]
fn dot_binds_tighter_than_mul_and_add() {
    assert_eq!(e("a + b . c * d"), "(+ a (* (. b c) d))");
    assert_eq!(e("a * b . c"), "(* a (. b c))");
    assert_eq!(
        e("intensity*lightcolor/L.L"),
        "(/ (* intensity lightcolor) (. L L))"
    );
    assert_eq!(e("refl * Cl * L . N"), "(* (* refl Cl) (. L N))");
}

#[test]
fn cross_sits_between_additive_and_multiplicative() {
    assert_eq!(e("a ^ b . c"), "(^ a (. b c))");
    assert_eq!(e("a * b ^ c * d"), "(^ (* a b) (* c d))");
    assert_eq!(e("a + b ^ c"), "(+ a (^ b c))");
    assert_eq!(e("a ^ b ^ c"), "(^ (^ a b) c)");
}

#[test]
fn unary_binds_tighter_than_dot() {
    assert_eq!(e("-a . b"), "(. (neg a) b)");
    assert_eq!(e("!a && b"), "(&& (not a) b)");
    assert_eq!(e("-a[1]"), "(neg (idx a 1))");
    assert_eq!(e("- -x"), "(neg (neg x))");
    assert_eq!(e("+x - -y"), "(- (pos x) (neg y))");
}

#[test]
fn assignment_is_right_associative_and_loosest() {
    assert_eq!(e("x = y = 1"), "(= x (= y 1))");
    assert_eq!(e("x += y *= 2"), "(+= x (*= y 2))");
    assert_eq!(e("x = a ? b : c"), "(= x (? a b c))");
    assert_eq!(e("x -= 1 + 2"), "(-= x (+ 1 2))");
    assert_eq!(e("x /= 2"), "(/= x 2)");
}

#[test]
fn conditional_is_right_associative() {
    assert_eq!(e("a ? b : c ? d : e"), "(? a b (? c d e))");
    assert_eq!(e("a ? b ? c : d : e"), "(? a (? b c d) e)");
    assert_eq!(e("a || b ? 1 : 2"), "(? (|| a b) 1 2)");
}

#[test]
fn logical_and_relational_levels() {
    assert_eq!(e("a || b && c"), "(|| a (&& b c))");
    assert_eq!(e("a == b < c"), "(== a (< b c))");
    assert_eq!(e("a < b + c"), "(< a (+ b c))");
    assert_eq!(
        e("a != b || c >= d && e <= f"),
        "(|| (!= a b) (&& (>= c d) (<= e f)))"
    );
    assert_eq!(e("a - b - c"), "(- (- a b) c)");
    assert_eq!(e("a / b * c"), "(* (/ a b) c)");
}

#[test]
fn increments_become_compound_assignments() {
    assert_eq!(e("i++"), "(+= i 1)");
    assert_eq!(e("i--"), "(-= i 1)");
    assert_eq!(e("++i"), "(+= i 1)");
    assert_eq!(e("--a[2]"), "(-= (idx a 2) 1)");
}

#[test]
fn literals() {
    assert_eq!(e("1"), "1");
    assert_eq!(e("-1"), "-1");
    assert_eq!(e("- -2.5"), "2.5");
    assert_eq!(e("-1 . x"), "(. -1 x)");
    assert_eq!(e("1.5"), "1.5");
    assert_eq!(e(".5"), "0.5");
    assert_eq!(e("1e-3"), "0.001");
    assert_eq!(e("2.5E2"), "250");
    assert_eq!(e("2."), "2");
    assert_eq!(e("1.f"), "1");
    assert_eq!(e("3f"), "3");
    assert_eq!(e(r#""a\tb\n\"q\"\\\101\x41""#), r#""a\tb\n\"q\"\\AA""#);
    assert_eq!(e(r#""ab" "cd""#), r#""abcd""#);
}

#[test]
fn casts_and_constructors() {
    assert_eq!(e("color (1,0,0)"), "(cast color (tuple 1 0 0))");
    assert_eq!(
        e(r#"color "hsv" (h,s,v)"#),
        r#"(cast color "hsv" (tuple h s v))"#
    );
    assert_eq!(
        e(r#"point "world" (0,0,0)"#),
        r#"(cast point "world" (tuple 0 0 0))"#
    );
    assert_eq!(e(r#"vector "object" V"#), r#"(cast vector "object" V)"#);
    assert_eq!(e(r#"matrix "shader" 1"#), r#"(cast matrix "shader" 1)"#);
    assert_eq!(e("normal N"), "(cast normal N)");
    assert_eq!(e("float x"), "(cast float x)");
    assert_eq!(e("float texture(m, s, t)"), "(cast float (texture m s t))");
    assert_eq!(e("float float a[1]"), "(cast float (cast float (idx a 1)))");
    assert_eq!(e("color c * 2"), "(* (cast color c) 2)");
    assert_eq!(e(r#"string "abc""#), r#"(cast string "abc")"#);
    assert_eq!(e("float(x) + 1"), "(+ (cast float x) 1)");
}

#[test]
fn calls_tuples_arrays_and_indexing() {
    assert_eq!(
        e(r#"texture("map"[1], s, t, "blur", .1)"#),
        r#"(texture (idx "map" 1) s t "blur" 0.1)"#
    );
    assert_eq!(
        e("texture(mapname[0], s, t)"),
        "(texture (idx mapname 0) s t)"
    );
    assert_eq!(e("f()"), "(f)");
    assert_eq!(e("f (a, g(b))"), "(f a (g b))");
    assert_eq!(e("(a)"), "a");
    assert_eq!(e("((a + b)) * c"), "(* (+ a b) c)");
    assert_eq!(
        e("(1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1)"),
        "(tuple 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1)"
    );
    assert_eq!(e("{1, 2, 3}"), "(array 1 2 3)");
    assert_eq!(e("{}"), "(array)");
    assert_eq!(e(r#"surface("Kd", kd)"#), r#"(surface "Kd" kd)"#);
    assert_eq!(e("a[i][j]"), "(idx (idx a i) j)");
    assert_eq!(e("floats + formula"), "(+ floats formula)");
}

#[test]
fn spans_cover_the_source_text() {
    let text = "surface t() { Ci = a + b . c; }";
    let f = ok(text);
    let Item::Shader(sh) = &f.items[0] else {
        panic!()
    };
    assert_eq!(
        &text[sh.name_span.start as usize..sh.name_span.end as usize],
        "t"
    );
    let StmtKind::Expr(x) = &sh.body.stmts[0].kind else {
        panic!()
    };
    assert_eq!(
        &text[x.span.start as usize..x.span.end as usize],
        "Ci = a + b . c"
    );
    let ExprKind::Assign { value, .. } = &x.kind else {
        panic!()
    };
    assert_eq!(
        &text[value.span.start as usize..value.span.end as usize],
        "a + b . c"
    );
    let s = sh.body.stmts[0].span;
    assert_eq!(&text[s.start as usize..s.end as usize], "Ci = a + b . c;");
}

// ------------------------------------------------------------------ definitions

#[test]
fn every_shader_kind_and_parameter_form() {
    let f = ok(r#"
        surface a(float Ka = 1, Kd = .5; output varying color c = 0; uniform float w[3] = {1,2,3};) {}
        displacement b() {}
        light c() {}
        volume d() {}
        imager e() {}
        transformation f() {}
        float g(float x, y; output color c; point p[]) { return x; }
        void h() { return; }
    "#);
    let kinds: Vec<String> = f
        .items
        .iter()
        .map(|i| match i {
            Item::Shader(s) => s.kind.name().to_string(),
            Item::Function(fd) => format!("fn {}", fd.ret.base.name()),
        })
        .collect();
    assert_eq!(
        kinds,
        [
            "surface",
            "displacement",
            "light",
            "volume",
            "imager",
            "transformation",
            "fn float",
            "fn void"
        ]
    );
    insta::assert_snapshot!("parameter_forms", outline(&f));
}

#[test]
fn debug_tree_of_small_shaders() {
    insta::assert_debug_snapshot!("constant_tree", ok(&input("constant")));
    insta::assert_debug_snapshot!("pointlight_tree", ok(&input("pointlight")));
}

#[test]
fn comments_are_accepted() {
    let f = ok("// line\nsurface /* inline */ t() { /* x */ Ci = 1; // end\n }");
    assert_eq!(f.items.len(), 1);
}

const STANDARD: [&str; 15] = [
    "constant",
    "matte",
    "metal",
    "shinymetal",
    "plastic",
    "paintedplastic",
    "ambientlight",
    "distantlight",
    "pointlight",
    "spotlight",
    "depthcue",
    "fog",
    "bumpy",
    "null",
    "background",
];

#[test]
fn all_standard_shaders_parse() {
    for name in STANDARD {
        let f = ok(&input(name));
        let [Item::Shader(sh)] = f.items.as_slice() else {
            panic!("{name}: expected one shader");
        };
        assert_eq!(sh.name, name);
        assert!(sh.params.iter().all(|p| p.default.is_some()), "{name}");
        insta::assert_snapshot!(format!("std_{name}"), outline(&f));
    }
}

#[test]
fn standard_shader_signatures() {
    let sig = |name: &str| -> Vec<String> {
        let f = ok(&input(name));
        let Item::Shader(sh) = &f.items[0] else {
            panic!()
        };
        sh.params
            .iter()
            .map(|p| format!("{} {}", p.ty.base.name(), p.name))
            .collect()
    };
    assert_eq!(
        sig("plastic"),
        [
            "float Ks",
            "float Kd",
            "float Ka",
            "float roughness",
            "color specularcolor"
        ]
    );
    assert_eq!(
        sig("spotlight"),
        [
            "float intensity",
            "color lightcolor",
            "point from",
            "point to",
            "float coneangle",
            "float conedeltaangle",
            "float beamdistribution"
        ]
    );
    assert_eq!(sig("depthcue").len(), 3);
    assert!(sig("null").is_empty());
}

#[test]
fn classic_shaders_parse() {
    for name in ["wood", "marble", "illum", "nested", "misc", "arman"] {
        let f = ok(&input(name));
        insta::assert_snapshot!(format!("classic_{name}"), outline(&f));
    }
}

#[test]
fn loop_levels_and_nested_functions() {
    let f = ok(&input("nested"));
    let Item::Shader(sh) = &f.items[0] else {
        panic!()
    };
    // The nested function keeps its output formals.
    let StmtKind::Function(acc) = &sh.body.stmts[1].kind else {
        panic!("nested function expected")
    };
    assert_eq!(acc.name, "accumulate");
    let outs: Vec<bool> = acc.params.iter().map(|p| p.output).collect();
    assert_eq!(outs, [false, true, true]);
    let StmtKind::VarDecl { is_extern, .. } = &acc.body.stmts[0].kind else {
        panic!()
    };
    assert!(is_extern);
    let text = outline(&f);
    assert!(text.contains("break 1"));
    assert!(text.contains("break 2"));
    assert!(text.contains("continue 1"));
}

// ------------------------------------------------------------------ errors

fn err(text: &str) -> String {
    let (tree, rendered, diags) = parse_named("bad.sl", text);
    assert!(diags.has_errors(), "expected an error for:\n{text}");
    let _ = tree;
    rendered
}

#[test]
fn missing_semicolon_points_at_the_line_end() {
    let r = err("surface t()\n{\n    float a = 1\n    Ci = a;\n}\n");
    insta::assert_snapshot!("err_missing_semicolon", r);
    assert!(r.contains("expected `;`"));
}

#[test]
fn unbalanced_braces_are_named() {
    let r = err("surface t()\n{\n    if (u > 0) {\n        Ci = 1;\n}\n");
    insta::assert_snapshot!("err_unbalanced_braces", r);
    assert!(r.contains("unbalanced"));
}

#[test]
fn reserved_word_as_name() {
    let r = err("surface t()\n{\n    float color = 1;\n}\n");
    insta::assert_snapshot!("err_reserved_word", r);
    assert!(r.contains("reserved word"));
}

#[test]
fn comma_between_parameter_types() {
    let r = err("surface t(float Ka = 1, color c = 1)\n{\n}\n");
    insta::assert_snapshot!("err_param_comma", r);
    assert!(r.contains("separated by `;`"));
}

#[test]
fn missing_default_and_bad_assignment() {
    let r = err("surface t(float Ka;)\n{\n    (a + b) = 1;\n    break 0;\n}\n");
    insta::assert_snapshot!("err_semantic_slips", r);
    assert!(r.contains("no default value"));
    assert!(r.contains("only a variable"));
}

#[test]
fn error_messages_avoid_rule_names() {
    for bad in [
        "surface t() { Ci = ; }",
        "surface t() { Ci = (1, 2; }",
        "surface t( { }",
        "surface t() { if Ci = 1; }",
        "surface () {}",
        "float f(float x) { return x }",
        "surface t() { Ci = a ? b; }",
        "surface t() { x[ = 1; }",
    ] {
        let (tree, r, diags) = parse_named("bad.sl", bad);
        assert!(tree.is_none(), "{bad}");
        assert_eq!(diags.error_count(), 1, "{bad}");
        for rule in [
            "expr",
            "ident",
            "stmt",
            "_stmt",
            "formal",
            "call_name",
            "EOI",
        ] {
            assert!(!r.contains(&format!("expected {rule}")), "{bad}:\n{r}");
        }
        assert!(r.contains("sl::syntax"), "{r}");
    }
}

#[test]
fn deep_nesting_is_refused_not_overflowed() {
    let deep = format!(
        "surface t() {{ Ci = {}1{}; }}",
        "(".repeat(5000),
        ")".repeat(5000)
    );
    assert!(err(&deep).contains("nested too deeply"));
    let chain = format!("surface t() {{ Ci = {}1; }}", "- ".repeat(5000));
    assert!(err(&chain).contains("nested too deeply"));
    let assigns = format!("surface t() {{ {}1; }}", "a += ".repeat(5000));
    assert!(err(&assigns).contains("nested too deeply"));
    let casts = format!("surface t() {{ Ci = {}1; }}", "float ".repeat(5000));
    assert!(err(&casts).contains("nested too deeply"));
    let ifs = format!("surface t() {{ {}; }}", "if (x) ".repeat(5000));
    assert!(parse_named("deep.sl", &ifs).2.has_errors());
    // Long comment banners are not operator chains.
    ok(&format!(
        "/* {} */\n// {}\nsurface t() {{ }}",
        "=-".repeat(600),
        "-".repeat(600)
    ));
    // Moderate nesting is fine.
    ok(&format!(
        "surface t() {{ Ci = {}1{}; }}",
        "(".repeat(40),
        ")".repeat(40)
    ));
}

#[test]
fn nesting_just_under_the_limits_fits_a_small_stack() {
    // Input just under the depth limits is accepted and built on a 1 MiB thread stack
    // (test threads get 2 MiB, rayon workers 2 MiB, the main thread 8 MiB).
    let inputs = [
        format!("surface t() {{ {}1; }}", "a = ".repeat(560)),
        format!("surface t() {{ Ci = {}1; }}", "- ".repeat(560)),
        format!("surface t() {{ Ci = {}1; }}", "color ".repeat(560)),
        format!(
            "surface t() {{ Ci = {}1{}; }}",
            "(".repeat(90),
            ")".repeat(90)
        ),
        format!(
            "surface t() {{ Ci = {}1{}; }}",
            "f(".repeat(90),
            ")".repeat(90)
        ),
        format!("surface t() {{ {}; }}", "if (x) ".repeat(280)),
        format!("surface t() {{ {}; }}", "while (x) ".repeat(280)),
        format!("surface t() {{ Ci = {}1; }}", "a ? b : ".repeat(560)),
    ];
    for text in inputs {
        let handle = std::thread::Builder::new()
            .stack_size(1 << 20)
            .spawn(move || {
                let (tree, _, diags) = parse_named("deep.sl", &text);
                (tree.is_some(), diags.error_count())
            })
            .expect("thread");
        let (built, errors) = handle.join().expect("no panic");
        assert!(built && errors == 0);
    }
}

// ------------------------------------------------------------------ robustness and speed

mod robustness {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 300, .. ProptestConfig::default() })]
        #[test]
        fn random_text_never_panics(s in "\\PC{0,200}") {
            let _ = parse_named("fuzz.sl", &s);
        }

        #[test]
        fn shader_like_text_never_panics(
            s in "(surface|float|color|point|\"hsv\"|[a-z]{1,3}|[0-9.e]{1,4}|[-+*/^.=<>!?:;,(){}\\[\\]]| |\n){0,80}"
        ) {
            let _ = parse_named("fuzz.sl", &s);
        }

        #[test]
        fn mutated_standard_shaders_never_panic(idx in 0usize..15, cut in 0usize..400, ins in "[-;{}()\\[\\]\"a.]") {
            let text = input(STANDARD[idx]);
            let cut = cut.min(text.len());
            let mut t = text.clone();
            if t.is_char_boundary(cut) {
                t.insert_str(cut, &ins);
            }
            let _ = parse_named("fuzz.sl", &t);
        }
    }
}

#[test]
fn fifty_kilobytes_parse_quickly() {
    let mut text = String::new();
    let body = input("marble");
    let mut n = 0;
    while text.len() < 50_000 {
        // Rename the definitions so the file stays a plausible library.
        text.push_str(
            &body
                .replace("turbulence", &format!("turbulence{n}"))
                .replace("marble", &format!("marble{n}")),
        );
        n += 1;
    }
    // Warm up (grammar statics), then time.
    ok("surface w() {}");
    let t0 = std::time::Instant::now();
    let f = ok(&text);
    let dt = t0.elapsed();
    assert!(f.items.len() >= 3 * n);
    eprintln!("parsed {} bytes in {:?}", text.len(), dt);
    // The target is well under 50 ms in debug; the bound here leaves room for a loaded CI box.
    assert!(dt.as_millis() < 250, "parsing took {dt:?}");
}

#[test]
fn a_late_error_in_a_large_file_is_reported_quickly() {
    let mut text = String::new();
    let body = input("marble");
    let mut n = 0;
    while text.len() < 50_000 {
        text.push_str(
            &body
                .replace("turbulence", &format!("turbulence{n}"))
                .replace("marble", &format!("marble{n}")),
        );
        n += 1;
    }
    text.push_str("surface broken() { Ci = 1 }\n");
    let t0 = std::time::Instant::now();
    let r = err(&text);
    let dt = t0.elapsed();
    eprintln!("error path over {} bytes took {:?}", text.len(), dt);
    assert!(r.contains("expected `;` or an operator, found `}`"), "{r}");
    assert!(dt.as_millis() < 1000, "error path took {dt:?}");
}

#[test]
fn several_syntax_errors_are_reported_without_cascades() {
    let text = "surface t()\n{\n    float a = 1\n    Ci = a;\n    if (a > 0)\n        Ci = (1, 2;\n    for (i = 0; i < 3 i += 1) {\n        Oi = ;\n    }\n    Ci = 1 + ;\n}\n";
    let (tree, r, diags) = parse_named("multi.sl", text);
    assert!(tree.is_none());
    insta::assert_snapshot!("err_several", r);
    assert_eq!(diags.error_count(), 4, "{r}");
}

#[test]
fn unterminated_string_and_stray_brace() {
    let r = err("surface t()\n{\n    string s = \"abc;\n    Ci = 1;\n}\n");
    insta::assert_snapshot!("err_unterminated_string", r);
    assert!(r.contains("unterminated string literal"));
    let r = err("surface t()\n{\n    Ci = 1;\n}\n}\n");
    insta::assert_snapshot!("err_stray_brace", r);
    assert!(r.contains("unmatched `}`"));
    let r = err("surface t()\n{\n    else Ci = 1;\n}\n");
    assert!(r.contains("must directly follow"), "{r}");
}
