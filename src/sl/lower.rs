//! Name resolution, type checking, detail inference and code generation in one walk.
//!
//! Input: a parsed [`ast::ShaderDef`] (with the file's top-level functions).
//! Output: an [`ir::Program`] and every diagnostic found (all collected, not just the first).
//! Invariants:
//! - user functions are inlined at each call with the argument types and details of that call,
//!   so overloading, polymorphism and detail fall out of the same walk; user functions shadow
//!   built-ins of the same name;
//! - a local declared without `uniform`/`varying` is uniform unless some assignment to it is
//!   varying or happens under varying control flow: the walk starts optimistic and restarts
//!   with the offending declaration marked varying until nothing changes (bounded by the number
//!   of declarations), so uniform work is done once per grid;
//! - every computation writes a fresh register; stores to variables are masked moves.

use std::collections::{HashMap, HashSet};
use std::rc::Rc;
use std::sync::Arc;

use glam::{Mat4, Vec3};

use crate::diag::{did_you_mean, Diag, Span};
use crate::sl::ast::*;
use crate::sl::builtins::{self, Builtin, Sig};
use crate::sl::ir::*;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Val {
    pub reg: Reg,
    pub ty: BaseType,
    pub varying: bool,
    pub array: Option<usize>,
}

#[derive(Clone, Debug)]
struct Var {
    ty: BaseType,
    array: Option<usize>,
    varying: bool,
    reg: Reg,
    writable: bool,
    /// Declared without an explicit detail: may be promoted to varying by a restart.
    candidate: Option<Span>,
    decl_span: Span,
    /// Varying-control depth at the declaration: stores at the same depth are unmasked
    /// for this variable's whole lifetime, so a uniform declared inside varying control
    /// flow (e.g. a loop counter of a function inlined in a varying loop) stays uniform.
    decl_ctx: u32,
}

/// The globals of the language: name, type, varying.
pub const GLOBALS: &[(&str, BaseType, bool)] = &[
    ("P", BaseType::Point, true),
    ("dPdu", BaseType::Vector, true),
    ("dPdv", BaseType::Vector, true),
    ("N", BaseType::Normal, true),
    ("Ng", BaseType::Normal, true),
    ("u", BaseType::Float, true),
    ("v", BaseType::Float, true),
    ("du", BaseType::Float, false),
    ("dv", BaseType::Float, false),
    ("s", BaseType::Float, true),
    ("t", BaseType::Float, true),
    ("Cs", BaseType::Color, true),
    ("Os", BaseType::Color, true),
    ("Ci", BaseType::Color, true),
    ("Oi", BaseType::Color, true),
    ("L", BaseType::Vector, true),
    ("Cl", BaseType::Color, true),
    ("Ol", BaseType::Color, true),
    ("Ps", BaseType::Point, true),
    ("E", BaseType::Point, false),
    ("I", BaseType::Vector, true),
    ("ncomps", BaseType::Float, false),
    ("time", BaseType::Float, false),
    ("dtime", BaseType::Float, false),
    ("dPdtime", BaseType::Vector, true),
    ("alpha", BaseType::Float, true),
];

/// Which globals a shader type may read and write (RISpec Tables 12.1–12.5).
fn global_access(kind: ShaderKind, name: &str) -> (bool, bool) {
    use ShaderKind::*;
    let rw = (true, true);
    let r = (true, false);
    let none = (false, false);
    match kind {
        Surface => match name {
            // P is writable too: PRMan and BMRT let surface shaders displace P for bump
            // and `calculatenormal` (e.g. Advanced RenderMan's `Displace`).
            "Ci" | "Oi" | "N" | "P" | "s" | "t" | "Cs" | "Os" => rw,
            "Ps" | "alpha" => none,
            "L" | "Cl" | "Ol" => r,
            _ => r,
        },
        Light => match name {
            "Cl" | "Ol" | "L" => rw,
            // `I` is readable as a PRMan extension (warned where used): the illuminated
            // surface's incident vector, which arbor binds for light shaders.
            "Ci" | "Oi" | "Cs" | "Os" | "alpha" => none,
            _ => r,
        },
        Displacement => match name {
            "P" | "N" | "s" | "t" => rw,
            "Ci" | "Oi" | "L" | "Cl" | "Ol" | "Ps" | "alpha" => none,
            _ => r,
        },
        Volume => match name {
            "Ci" | "Oi" => rw,
            // L and Cl inside `illuminance` (atmosphere shaders gather in-scattered light).
            "P" | "I" | "E" | "ncomps" | "time" | "dtime" | "L" | "Cl" | "Ol" => r,
            _ => none,
        },
        Imager => match name {
            "Ci" | "Oi" | "alpha" => rw,
            "P" | "ncomps" | "time" | "dtime" => r,
            _ => none,
        },
        Transformation => match name {
            "P" => rw,
            _ => r,
        },
    }
}

#[derive(Clone)]
struct FuncEntry {
    def: Rc<FuncDef>,
    /// Scope depth at the definition: the body sees only scopes up to here.
    depth: usize,
}

struct LoopFrame {
    varying_ctx: u32,
    span: Span,
}

struct FuncFrame {
    ret: Option<Var>,
    varying_ctx: u32,
    span: Span,
}

struct Lowerer<'a> {
    kind: ShaderKind,
    regs: Vec<RegInfo>,
    consts: Vec<(Reg, Const)>,
    const_f: HashMap<u32, Reg>,
    const_s: HashMap<String, Reg>,
    const_values: HashMap<Reg, Const>,
    scopes: Vec<HashMap<String, Var>>,
    funcs: Vec<HashMap<String, Vec<FuncEntry>>>,
    globals: Vec<GlobalInfo>,
    varying_ctx: u32,
    forced: &'a HashSet<Span>,
    newly_forced: HashSet<Span>,
    loops: Vec<LoopFrame>,
    fn_frames: Vec<FuncFrame>,
    inline_stack: Vec<String>,
    out: Vec<Vec<Instr>>,
    diags: Vec<Diag>,
    in_illuminance: u32,
    in_light_construct: u32,
    error_reg: Reg,
    /// Registers below this are globals; those read or written are kept in the program.
    globals_end: usize,
    used_globals: HashSet<Reg>,
    /// Non-standard extensions already warned about in this shader (one warning each).
    warned: HashSet<&'static str>,
    /// Lowering the value stored into a variable declared `uniform`: `random()` there gives one
    /// number per grid (RISpec §15.1; Aqsis' randgrid.sl colours each grid this way).
    uniform_target: bool,
    /// Declarations written `uniform` (their `candidate` is set too, for demotion).
    explicit_uniform: HashSet<Span>,
}

fn ty_name(ty: BaseType, array: Option<usize>) -> String {
    match array {
        Some(n) => format!("{}[{}]", ty.name(), n),
        None => ty.name().to_string(),
    }
}

/// Compiles one shader definition. `functions` are the file's top-level functions.
pub fn lower_shader(
    def: &ShaderDef,
    functions: &[FuncDef],
) -> Result<(Program, Vec<Diag>), Vec<Diag>> {
    let mut forced: HashSet<Span> = HashSet::new();
    // Each restart marks at least one more declaration varying; bounded.
    for _ in 0..256 {
        let snapshot = forced.clone();
        let mut lw = Lowerer::new(def.kind, &snapshot);
        let prog = lw.shader(def, functions);
        let newly: Vec<Span> = lw.newly_forced.drain().collect();
        let diags = std::mem::take(&mut lw.diags);
        drop(lw);
        if !newly.is_empty() {
            let grew = newly.iter().any(|s| !forced.contains(s));
            forced.extend(newly);
            if grew {
                continue;
            }
        }
        let (errors, warnings): (Vec<Diag>, Vec<Diag>) =
            diags.into_iter().partition(|d| d.is_error());
        if !errors.is_empty() {
            let mut all = errors;
            all.extend(warnings);
            return Err(all);
        }
        return Ok((prog, warnings));
    }
    Err(vec![Diag::error(
        "sl::internal",
        "detail inference did not converge",
    )
    .label(def.span, "in this shader")])
}

impl<'a> Lowerer<'a> {
    fn new(kind: ShaderKind, forced: &'a HashSet<Span>) -> Lowerer<'a> {
        let mut lw = Lowerer {
            kind,
            regs: Vec::new(),
            consts: Vec::new(),
            const_f: HashMap::new(),
            const_s: HashMap::new(),
            const_values: HashMap::new(),
            scopes: vec![HashMap::new()],
            funcs: vec![HashMap::new()],
            globals: Vec::new(),
            varying_ctx: 0,
            forced,
            newly_forced: HashSet::new(),
            loops: Vec::new(),
            fn_frames: Vec::new(),
            inline_stack: Vec::new(),
            out: vec![Vec::new()],
            diags: Vec::new(),
            in_illuminance: 0,
            in_light_construct: 0,
            error_reg: 0,
            globals_end: 0,
            used_globals: HashSet::new(),
            warned: HashSet::new(),
            uniform_target: false,
            explicit_uniform: HashSet::new(),
        };
        lw.error_reg = lw.const_float(0.0);
        lw
    }

    // ---- registers and constants ----

    fn new_reg(&mut self, kind: Kind, varying: bool) -> Reg {
        self.regs.push(RegInfo { kind, varying });
        (self.regs.len() - 1) as Reg
    }

    fn temp(&mut self, ty: BaseType, varying: bool) -> Val {
        let reg = self.new_reg(Kind::of(ty), varying);
        Val {
            reg,
            ty,
            varying,
            array: None,
        }
    }

    fn const_float(&mut self, x: f32) -> Reg {
        if let Some(&r) = self.const_f.get(&x.to_bits()) {
            return r;
        }
        let r = self.new_reg(Kind::Float, false);
        self.consts.push((r, Const::F(x)));
        self.const_values.insert(r, Const::F(x));
        self.const_f.insert(x.to_bits(), r);
        r
    }

    fn const_val(&mut self, c: Const, ty: BaseType) -> Val {
        let reg = match &c {
            Const::F(x) => self.const_float(*x),
            Const::S(s) => {
                if let Some(&r) = self.const_s.get(&**s) {
                    r
                } else {
                    let r = self.new_reg(Kind::Str, false);
                    self.const_s.insert(s.to_string(), r);
                    self.consts.push((r, c.clone()));
                    self.const_values.insert(r, c.clone());
                    r
                }
            }
            Const::T(_) => {
                let r = self.new_reg(Kind::Triple, false);
                self.consts.push((r, c.clone()));
                self.const_values.insert(r, c.clone());
                r
            }
            Const::M(_) => {
                let r = self.new_reg(Kind::Matrix, false);
                self.consts.push((r, c.clone()));
                self.const_values.insert(r, c.clone());
                r
            }
        };
        Val {
            reg,
            ty,
            varying: false,
            array: None,
        }
    }

    fn const_of(&self, v: &Val) -> Option<&Const> {
        if v.varying {
            return None;
        }
        self.const_values.get(&v.reg)
    }

    fn emit(&mut self, i: Instr) {
        self.out.last_mut().expect("instruction buffer").push(i);
    }

    fn with_block<T>(&mut self, f: impl FnOnce(&mut Self) -> T) -> (Vec<Instr>, T) {
        self.out.push(Vec::new());
        let t = f(self);
        let block = self.out.pop().unwrap_or_default();
        (block, t)
    }

    fn error(&mut self, d: Diag) -> Val {
        self.diags.push(d);
        self.error_val()
    }

    /// Whether values stored into `var` are uniform by declaration (`uniform` locals and
    /// parameters), not merely uniform so far by inference.
    fn is_uniform_target(&self, var: &Var) -> bool {
        !var.varying && (var.candidate.is_none() || self.explicit_uniform.contains(&var.decl_span))
    }

    /// One warning per shader for a recognised non-standard extension.
    fn warn_extension(&mut self, key: &'static str, span: Span, msg: &str) {
        if self.warned.insert(key) {
            self.diags.push(
                Diag::warning("sl::extension", msg.to_string())
                    .label(span, "non-standard")
                    .help("written for another renderer: arbor accepts it as the message says"),
            );
        }
    }

    /// Functions of other renderers (PRMan, BMRT, Pixie, Aqsis) that arbor cannot compute:
    /// the arguments are type-checked, one warning names the function, and the call yields
    /// the value a renderer without the feature gives (no occlusion, no indirect light,
    /// nothing baked). None for any other name.
    fn extension_call(&mut self, name: &str, args: &[Expr], span: Span) -> Option<Val> {
        let (key, ty, value, what): (&'static str, BaseType, Const, &str) = match name {
            "caustic" => ("caustic", BaseType::Color, Const::T(Vec3::ZERO), "black"),
            "photonmap" => ("photonmap", BaseType::Color, Const::T(Vec3::ZERO), "black"),
            "subsurface" => ("subsurface", BaseType::Color, Const::T(Vec3::ZERO), "black"),
            "bake" => (
                "bake",
                BaseType::Float,
                Const::F(0.0),
                "0 (nothing written)",
            ),
            "bake3d" => (
                "bake3d",
                BaseType::Float,
                Const::F(0.0),
                "0 (nothing written)",
            ),
            "texture3d" => (
                "texture3d",
                BaseType::Float,
                Const::F(0.0),
                "0 (nothing read)",
            ),
            "rayhittest" => (
                "rayhittest",
                BaseType::Float,
                Const::F(1.0e30),
                "1e30 (every ray misses)",
            ),
            "isindirectray" => ("isindirectray", BaseType::Float, Const::F(0.0), "0"),
            "iscameraray" => ("iscameraray", BaseType::Float, Const::F(1.0), "1"),
            _ => return None,
        };
        for a in args {
            self.expr(a, None);
        }
        self.warn_extension(
            key,
            span,
            &format!(
                "`{name}` is a non-standard extension arbor does not compute; it returns {what}"
            ),
        );
        Some(self.const_val(value, ty))
    }

    /// A call of a name that is neither a built-in nor a function of the shader, and not
    /// near one: published shaders call compiled C plug-ins (PRMan and Aqsis DSO shadeops,
    /// e.g. Aqsis's volume example's `sample_vol`) this way. arbor cannot load those, so the
    /// call warns by name and yields zero of the type the context asks for (float when it
    /// asks nothing), and the rest of the shader still runs.
    fn dso_shadeop(&mut self, name: &str, span: Span, hint: Option<BaseType>) -> Val {
        let ty = match hint {
            Some(t @ (BaseType::Color | BaseType::Point | BaseType::Vector | BaseType::Normal)) => {
                t
            }
            Some(BaseType::String) => BaseType::String,
            Some(BaseType::Matrix) => BaseType::Matrix,
            _ => BaseType::Float,
        };
        let (value, what) = match ty {
            BaseType::String => (Const::S("".into()), "\"\""),
            BaseType::Matrix => (Const::M(Mat4::ZERO), "a zero matrix"),
            BaseType::Float => (Const::F(0.0), "0"),
            _ => (Const::T(Vec3::ZERO), "(0, 0, 0)"),
        };
        self.diags.push(
            Diag::warning(
                "sl::dso-shadeop",
                format!(
                    "`{name}` is not a built-in or a function of this shader: taken as a DSO \
                     shadeop (a compiled C plug-in), which arbor cannot load; it returns {what}"
                ),
            )
            .label(span, "not defined here")
            .help(format!(
                "define `{name}` as a shading-language function, or include the header that \
                 does, if it is not a plug-in"
            )),
        );
        self.const_val(value, ty)
    }

    fn error_val(&self) -> Val {
        Val {
            reg: self.error_reg,
            ty: BaseType::Float,
            varying: false,
            array: None,
        }
    }

    // ---- scopes ----

    fn lookup(&self, name: &str) -> Option<Var> {
        self.scopes.iter().rev().find_map(|s| s.get(name)).cloned()
    }

    fn declare(&mut self, name: &str, var: Var) {
        if let Some(s) = self.scopes.last_mut() {
            s.insert(name.to_string(), var);
        }
    }

    fn lookup_funcs(&self, name: &str) -> Option<Vec<FuncEntry>> {
        self.funcs.iter().rev().find_map(|s| s.get(name)).cloned()
    }

    fn push_scope(&mut self) {
        self.scopes.push(HashMap::new());
        self.funcs.push(HashMap::new());
    }

    fn pop_scope(&mut self) {
        self.scopes.pop();
        self.funcs.pop();
    }

    fn define_function(&mut self, f: &FuncDef) {
        let depth = self.scopes.len();
        let entry = FuncEntry {
            def: Rc::new(f.clone()),
            depth,
        };
        if let Some(s) = self.funcs.last_mut() {
            s.entry(f.name.clone()).or_default().push(entry);
        }
    }

    // ---- the shader ----

    fn shader(&mut self, def: &ShaderDef, functions: &[FuncDef]) -> Program {
        // Scope 0: globals.
        for &(name, ty, varying) in GLOBALS {
            let (readable, writable) = global_access(self.kind, name);
            if !readable && !writable {
                continue;
            }
            let reg = self.new_reg(Kind::of(ty), varying);
            self.globals.push(GlobalInfo {
                name,
                reg,
                written: false,
            });
            self.declare(
                name,
                Var {
                    ty,
                    array: None,
                    varying,
                    reg,
                    writable,
                    candidate: None,
                    decl_span: def.span,
                    decl_ctx: self.varying_ctx,
                },
            );
        }
        self.globals_end = self.regs.len();
        for f in functions {
            self.define_function(f);
        }
        self.push_scope();
        // Parameters: defaults computed in `init`.
        let mut params = Vec::new();
        let (init, ()) = self.with_block(|lw| {
            for p in &def.params {
                let varying = p.ty.detail == Some(Detail::Varying);
                let array = match p.array {
                    Some(ArraySpec::Sized(n)) => Some(n),
                    Some(ArraySpec::Unsized) => {
                        // The length comes from the default.
                        match &p.default {
                            Some(Expr {
                                kind: ExprKind::ArrayLit(items),
                                ..
                            }) => Some(items.len()),
                            _ => {
                                lw.diags.push(
                                    Diag::error(
                                        "sl::array",
                                        format!("parameter `{}` has no array length", p.name),
                                    )
                                    .label(p.span, "declared here")
                                    .help("give the array a size or an initialiser like {1, 2, 3}"),
                                );
                                Some(1)
                            }
                        }
                    }
                    None => None,
                };
                let reg = lw.alloc_var_regs(p.ty.base, array, varying);
                let var = Var {
                    ty: p.ty.base,
                    array,
                    varying,
                    reg,
                    writable: true,
                    candidate: None,
                    decl_span: p.span,
                    decl_ctx: 0,
                };
                let mut default_text = String::from("(computed)");
                match &p.default {
                    Some(e) => {
                        lw.init_var(&var, e);
                        if let ExprKind::Float(x) = e.kind {
                            default_text = format!("{x}");
                        } else if let ExprKind::Str(s) = &e.kind {
                            default_text = format!("{s:?}");
                        }
                    }
                    // An output parameter may go without a default (PRMan): it starts at
                    // zero, as every fresh register does.
                    None if p.output => default_text = String::from("0"),
                    None => lw.diags.push(
                        Diag::error(
                            "sl::param",
                            format!("shader parameter `{}` has no default value", p.name),
                        )
                        .label(p.span, "parameter")
                        .help(format!(
                            "every shader parameter needs a default: `{} = …`",
                            p.name
                        )),
                    ),
                }
                params.push(ParamInfo {
                    name: p.name.clone(),
                    ty: p.ty.base,
                    array,
                    varying,
                    output: p.output,
                    reg,
                    default_text,
                });
                lw.declare(&p.name, var);
            }
        });
        let (body, ()) = self.with_block(|lw| lw.block_stmts(&def.body));
        self.pop_scope();
        // L, Cl, Ol are set by illuminance/illuminate; keep them when those constructs appear.
        let used = std::mem::take(&mut self.used_globals);
        let mut globals = std::mem::take(&mut self.globals);
        globals
            .retain(|g| used.contains(&g.reg) || matches!(g.name, "L" | "Cl" | "Ol" | "du" | "dv"));
        let mut prog = Program {
            name: def.name.clone(),
            kind: def.kind,
            regs: std::mem::take(&mut self.regs),
            consts: std::mem::take(&mut self.consts),
            params,
            globals,
            init,
            body,
            movable: Vec::new(),
            full_width: Vec::new(),
            span: def.span,
        };
        prog.movable = prog.movable_temps();
        prog.full_width = prog.full_width_regs();
        prog.mark_compact_loops();
        prog
    }

    fn alloc_var_regs(&mut self, ty: BaseType, array: Option<usize>, varying: bool) -> Reg {
        let n = array.unwrap_or(1).max(1);
        let first = self.new_reg(Kind::of(ty), varying);
        for _ in 1..n {
            self.new_reg(Kind::of(ty), varying);
        }
        first
    }

    fn init_var(&mut self, var: &Var, e: &Expr) {
        match (&e.kind, var.array) {
            (ExprKind::ArrayLit(items), Some(n)) => {
                if items.len() < n {
                    self.diags.push(
                        Diag::error(
                            "sl::array",
                            format!("array of {n} initialised with {} values", items.len()),
                        )
                        .label(e.span, "initialiser"),
                    );
                } else if items.len() > n {
                    // Aqsis's regression shader `splinetst` gives a colour map[4] five
                    // values; the array keeps the first n, as Aqsis's compiler did.
                    self.diags.push(
                        Diag::warning(
                            "sl::array",
                            format!(
                                "array of {n} initialised with {} values; the last {} are ignored",
                                items.len(),
                                items.len() - n
                            ),
                        )
                        .label(e.span, "initialiser"),
                    );
                }
                for (i, item) in items.iter().enumerate().take(n) {
                    let v = self.expr(item, Some(var.ty));
                    let v = self.coerce(v, var.ty, item.span);
                    self.store_reg(var, var.reg + i as Reg, v, item.span);
                }
            }
            (_, Some(_)) => {
                let v = self.expr(e, Some(var.ty));
                if let Some(n) = v.array {
                    for i in 0..n.min(var.array.unwrap_or(0)) {
                        let ev = Val {
                            reg: v.reg + i as Reg,
                            ty: v.ty,
                            varying: v.varying,
                            array: None,
                        };
                        self.store_reg(var, var.reg + i as Reg, ev, e.span);
                    }
                } else {
                    self.diags.push(
                        Diag::error(
                            "sl::array",
                            "an array must be initialised with {…} or another array",
                        )
                        .label(e.span, "not an array"),
                    );
                }
            }
            (ExprKind::ArrayLit(_), None) => {
                self.diags.push(
                    Diag::error("sl::array", "{…} initialises arrays only")
                        .label(e.span, "not an array variable"),
                );
            }
            _ => {
                let saved = self.uniform_target;
                self.uniform_target = self.is_uniform_target(var);
                let v = self.expr(e, Some(var.ty));
                self.uniform_target = saved;
                let v = self.coerce(v, var.ty, e.span);
                self.store_reg(var, var.reg, v, e.span);
            }
        }
    }

    // ---- statements ----

    fn block_stmts(&mut self, b: &Block) {
        for s in &b.stmts {
            self.stmt(s);
        }
    }

    fn stmt(&mut self, s: &Stmt) {
        match &s.kind {
            StmtKind::Empty => {}
            StmtKind::Expr(e) => {
                self.expr(e, None);
            }
            StmtKind::Block(b) => {
                self.push_scope();
                self.block_stmts(b);
                self.pop_scope();
            }
            StmtKind::Function(f) => self.define_function(f),
            StmtKind::VarDecl {
                is_extern,
                output: _,
                ty,
                vars,
            } => {
                for v in vars {
                    if *is_extern {
                        match self.lookup(&v.name) {
                            Some(var) => {
                                if var.ty != ty.base {
                                    self.diags.push(
                                        Diag::error(
                                            "sl::type",
                                            format!(
                                                "extern `{}` is declared {} but the outer variable is {}",
                                                v.name,
                                                ty.base.name(),
                                                var.ty.name()
                                            ),
                                        )
                                        .label(v.span, "extern declaration"),
                                    );
                                }
                                self.declare(&v.name, var);
                            }
                            None => self.diags.push(
                                Diag::error(
                                    "sl::name",
                                    format!("extern `{}` names no outer variable", v.name),
                                )
                                .label(v.span, "not found in an enclosing scope"),
                            ),
                        }
                        continue;
                    }
                    let array = match v.array {
                        Some(ArraySpec::Sized(n)) => Some(n),
                        Some(ArraySpec::Unsized) => match &v.init {
                            Some(Expr {
                                kind: ExprKind::ArrayLit(items),
                                ..
                            }) => Some(items.len()),
                            _ => {
                                self.diags.push(
                                    Diag::error(
                                        "sl::array",
                                        format!("local array `{}` needs a size", v.name),
                                    )
                                    .label(v.span, "declared here"),
                                );
                                Some(1)
                            }
                        },
                        None => None,
                    };
                    let (varying, candidate) = match ty.detail {
                        Some(Detail::Varying) => (true, None),
                        // An explicitly uniform local that is assigned a varying value or
                        // under deeper varying control flow is demoted to varying with a
                        // warning (PRMan/BMRT-era shaders rely on this), not rejected.
                        Some(Detail::Uniform) => {
                            self.explicit_uniform.insert(v.span);
                            let demoted = self.forced.contains(&v.span);
                            if demoted {
                                self.diags.push(
                                    Diag::warning(
                                        "sl::detail",
                                        format!(
                                            "uniform `{}` is assigned a varying value or under \
                                             varying control flow; it is treated as varying",
                                            v.name
                                        ),
                                    )
                                    .label(v.span, "declared uniform here")
                                    .help(
                                        "declare the variable `varying` (or leave the detail out)",
                                    ),
                                );
                            }
                            (demoted, Some(v.span))
                        }
                        None => (self.forced.contains(&v.span), Some(v.span)),
                    };
                    let reg = self.alloc_var_regs(ty.base, array, varying);
                    let var = Var {
                        ty: ty.base,
                        array,
                        varying,
                        reg,
                        writable: true,
                        candidate,
                        decl_span: v.span,
                        decl_ctx: self.varying_ctx,
                    };
                    // Declared inside varying control flow: the variable is set under a mask.
                    if let Some(init) = &v.init {
                        self.init_var(&var, init);
                    }
                    self.declare(&v.name, var);
                }
            }
            StmtKind::If {
                cond,
                then,
                otherwise,
            } => {
                let c = self.cond(cond);
                if c.varying {
                    self.varying_ctx += 1;
                }
                let (tb, ()) = self.with_block(|lw| lw.scoped_stmt(then));
                let (eb, ()) = self.with_block(|lw| {
                    if let Some(o) = otherwise {
                        lw.scoped_stmt(o)
                    }
                });
                if c.varying {
                    self.varying_ctx -= 1;
                }
                self.emit(Instr::If {
                    cond: c.reg,
                    then: tb,
                    otherwise: eb,
                });
            }
            StmtKind::While { cond, body } => self.lower_loop(s.span, None, Some(cond), None, body),
            StmtKind::For {
                init,
                cond,
                step,
                body,
            } => self.lower_loop(s.span, init.as_ref(), cond.as_ref(), step.as_ref(), body),
            StmtKind::Break(n) | StmtKind::Continue(n) => {
                let n = (*n).max(1);
                if n as usize > self.loops.len() {
                    let mut d = Diag::error(
                        "sl::control",
                        format!("`break`/`continue` {n} is outside {n} loops"),
                    )
                    .label(s.span, "here");
                    if let Some(f) = self.inline_stack.last() {
                        d = d.help(format!(
                            "inside function `{f}` only its own loops count; use `return` to leave the function"
                        ));
                    }
                    self.diags.push(d);
                    return;
                }
                let frame = &self.loops[self.loops.len() - n as usize];
                if self.varying_ctx > frame.varying_ctx && !self.forced.contains(&frame.span) {
                    self.newly_forced.insert(frame.span);
                }
                self.emit(if matches!(s.kind, StmtKind::Break(_)) {
                    Instr::Break(n)
                } else {
                    Instr::Continue(n)
                });
            }
            StmtKind::Return(e) => {
                let Some(frame) = self.fn_frames.last() else {
                    // `return` in a shader body ends the shader (allowed by some compilers).
                    self.emit(Instr::Return);
                    return;
                };
                let (fspan, fctx) = (frame.span, frame.varying_ctx);
                let ret = frame.ret.clone();
                if self.varying_ctx > fctx && !self.forced.contains(&fspan) {
                    self.newly_forced.insert(fspan);
                }
                match (e, ret) {
                    (Some(e), Some(var)) => {
                        let v = self.expr(e, Some(var.ty));
                        let v = self.coerce(v, var.ty, e.span);
                        self.store(&var, v, e.span);
                    }
                    (Some(e), None) => {
                        self.diags.push(
                            Diag::error("sl::type", "a void function returns no value")
                                .label(e.span, "value"),
                        );
                    }
                    (None, Some(_)) => {
                        self.diags.push(
                            Diag::error("sl::type", "this function must return a value")
                                .label(s.span, "bare return"),
                        );
                    }
                    (None, None) => {}
                }
                self.emit(Instr::Return);
            }
            StmtKind::Illuminance { args, body } => self.illuminance(s.span, args, body),
            StmtKind::Illuminate { args, body } => {
                if self.kind != ShaderKind::Light {
                    self.diags.push(
                        Diag::error(
                            "sl::context",
                            "`illuminate` is only allowed in light shaders",
                        )
                        .label(s.span, "here"),
                    );
                }
                let pos = match args.first() {
                    Some(e) => {
                        let v = self.expr(e, Some(BaseType::Point));
                        self.coerce(v, BaseType::Point, e.span)
                    }
                    None => {
                        self.diags.push(
                            Diag::error("sl::call", "`illuminate` needs a position")
                                .label(s.span, "here"),
                        );
                        self.error_val()
                    }
                };
                let axis = self.axis_angle(&args[args.len().min(1)..], s.span);
                self.in_light_construct += 1;
                self.varying_ctx += 1;
                let (b, ()) = self.with_block(|lw| lw.scoped_stmt(body));
                self.varying_ctx -= 1;
                self.in_light_construct -= 1;
                self.emit(Instr::Illuminate {
                    pos: pos.reg,
                    axis,
                    body: b,
                });
            }
            StmtKind::Solar { args, body } => {
                if self.kind != ShaderKind::Light {
                    self.diags.push(
                        Diag::error("sl::context", "`solar` is only allowed in light shaders")
                            .label(s.span, "here"),
                    );
                }
                let axis = self.axis_angle(args, s.span);
                self.in_light_construct += 1;
                self.varying_ctx += 1;
                let (b, ()) = self.with_block(|lw| lw.scoped_stmt(body));
                self.varying_ctx -= 1;
                self.in_light_construct -= 1;
                self.emit(Instr::Solar { axis, body: b });
            }
            StmtKind::Gather {
                args,
                body,
                otherwise,
            } => {
                // gather(category, P, dir, angle, samples, "name", var, …)
                let tys = [
                    BaseType::String,
                    BaseType::Point,
                    BaseType::Vector,
                    BaseType::Float,
                    BaseType::Float,
                ];
                if args.len() < 5 {
                    self.diags.push(
                        Diag::error(
                            "sl::call",
                            format!("`gather` takes (category, P, dir, angle, samples, …), found {} arguments", args.len()),
                        )
                        .label(s.span, "gather")
                        .help("gather(\"illuminance\", P, R, 0, 4, \"surface:Ci\", c) { … }"),
                    );
                }
                let mut regs = Vec::new();
                for (k, a) in args.iter().take(5).enumerate() {
                    let v = self.expr(a, Some(tys[k]));
                    let v = self.coerce(v, tys[k], a.span);
                    regs.push(v.reg);
                }
                while regs.len() < 5 {
                    regs.push(self.const_float(0.0));
                }
                // Output pairs: a literal name and a variable.
                let mut outs: Vec<(String, Var, Val, Span)> = Vec::new();
                let mut k = 5;
                while k < args.len() {
                    let name = match &args[k].kind {
                        ExprKind::Str(n) => n.clone(),
                        _ => {
                            self.expr(&args[k], None);
                            self.diags.push(
                                Diag::error(
                                    "sl::call",
                                    "`gather` output names are string literals",
                                )
                                .label(args[k].span, "not a literal name"),
                            );
                            k += 2;
                            continue;
                        }
                    };
                    // PRMan's gather options are inputs, not outputs.
                    const GATHER_INPUTS: &[&str] = &[
                        "bias",
                        "label",
                        "maxdist",
                        "samplebase",
                        "distribution",
                        "subset",
                        "hitmode",
                        "hitsides",
                        "othreshold",
                        "raytype",
                        "samplepattern",
                    ];
                    if GATHER_INPUTS.contains(&name.as_str()) {
                        self.unused_ray_params(
                            "gather",
                            &args[k..(k + 2).min(args.len())],
                            0,
                            &["label"],
                        );
                        k += 2;
                        continue;
                    }
                    let Some(target) = args.get(k + 1) else {
                        self.diags.push(
                            Diag::error(
                                "sl::call",
                                format!("`gather` output \"{name}\" without a variable"),
                            )
                            .label(args[k].span, "no variable"),
                        );
                        break;
                    };
                    let var = match &target.kind {
                        ExprKind::Ident(n) => self.lookup(n).filter(|v| v.writable),
                        _ => None,
                    };
                    let Some(var) = var else {
                        self.diags.push(
                            Diag::error(
                                "sl::call",
                                format!("`gather` stores \"{name}\" into a writable variable"),
                            )
                            .label(target.span, "not a writable variable"),
                        );
                        k += 2;
                        continue;
                    };
                    let known = matches!(
                        name.as_str(),
                        "surface:Ci"
                            | "surface:Oi"
                            | "volume:Ci"
                            | "volume:Oi"
                            | "ray:length"
                            | "ray:direction"
                            | "ray:origin"
                            | "primitive:P"
                            | "surface:P"
                    );
                    if !known {
                        self.diags.push(
                            Diag::warning("sl::unsupported", format!("`gather` output \"{name}\" is not computed by arbor; the variable keeps its value"))
                                .label(args[k].span, "unsupported output")
                                .help("arbor gives surface:Ci, surface:Oi, volume:Ci, volume:Oi, ray:length, ray:direction, ray:origin, primitive:P"),
                        );
                    }
                    let want = if name == "ray:length" {
                        BaseType::Float
                    } else {
                        BaseType::Color
                    };
                    let ty_ok = if want == BaseType::Float {
                        var.ty == BaseType::Float
                    } else {
                        var.ty.is_triple()
                    };
                    if !ty_ok {
                        self.diags.push(
                            Diag::error(
                                "sl::type",
                                format!(
                                    "`gather` output \"{name}\" needs a {} variable",
                                    if want == BaseType::Float {
                                        "float"
                                    } else {
                                        "triple"
                                    }
                                ),
                            )
                            .label(target.span, "wrong type"),
                        );
                        k += 2;
                        continue;
                    }
                    let t = self.temp(var.ty, true);
                    outs.push((name, var, t, target.span));
                    k += 2;
                }
                self.varying_ctx += 1;
                let (bb, ()) = self.with_block(|lw| {
                    for (_, var, t, sp) in &outs {
                        lw.store_reg(var, var.reg, *t, *sp);
                        lw.mark_written(var.reg);
                    }
                    lw.scoped_stmt(body)
                });
                let (eb, ()) = self.with_block(|lw| {
                    if let Some(o) = otherwise {
                        lw.scoped_stmt(o)
                    }
                });
                self.varying_ctx -= 1;
                self.emit(Instr::Gather {
                    pos: regs[1],
                    dir: regs[2],
                    angle: regs[3],
                    samples: regs[4],
                    outputs: outs.iter().map(|(n, _, t, _)| (n.clone(), t.reg)).collect(),
                    body: bb,
                    otherwise: eb,
                });
            }
        }
    }

    fn scoped_stmt(&mut self, s: &Stmt) {
        // A bare declaration as the body (`solar() vector Lt = -L;`, written by shaders
        // that meant the construct to cover the rest of the body) declares into the
        // enclosing scope, as Aqsis's compiler does; a fresh scope would make the name
        // vanish before anything could use it.
        if matches!(s.kind, StmtKind::VarDecl { .. }) {
            self.stmt(s);
            return;
        }
        self.push_scope();
        self.stmt(s);
        self.pop_scope();
    }

    fn axis_angle(&mut self, args: &[Expr], span: Span) -> Option<(Reg, Reg)> {
        match args.len() {
            0 => None,
            2 => {
                let a = self.expr(&args[0], Some(BaseType::Vector));
                let a = self.coerce(a, BaseType::Vector, args[0].span);
                let b = self.expr(&args[1], Some(BaseType::Float));
                let b = self.coerce(b, BaseType::Float, args[1].span);
                Some((a.reg, b.reg))
            }
            n => {
                self.diags.push(
                    Diag::error(
                        "sl::call",
                        format!("expected an axis and an angle, found {n} arguments"),
                    )
                    .label(span, "here"),
                );
                None
            }
        }
    }

    fn illuminance(&mut self, span: Span, args: &[Expr], body: &Stmt) {
        if self.kind == ShaderKind::Light {
            self.diags.push(
                Diag::error(
                    "sl::context",
                    "`illuminance` is not allowed in light shaders",
                )
                .label(span, "here"),
            );
        }
        let mut rest = args;
        let mut category = None;
        if let Some(first) = rest.first() {
            let v = self.expr(first, None);
            if v.ty == BaseType::String {
                category = Some(v.reg);
                rest = &rest[1..];
            } else if !v.ty.is_triple() {
                self.diags.push(
                    Diag::error("sl::call", "`illuminance` needs a position")
                        .label(first.span, "not a point"),
                );
            }
        }
        let pos = match rest.first() {
            Some(e) => {
                let v = self.expr(e, Some(BaseType::Point));
                self.coerce(v, BaseType::Point, e.span)
            }
            None => {
                self.diags.push(
                    Diag::error("sl::call", "`illuminance` needs a position").label(span, "here"),
                );
                self.error_val()
            }
        };
        // PRMan's and 3Delight's optional `"name", value` pairs after the axis and angle
        // (or right after the position): `illuminance("", P, N, PI/2, "light:__nondiffuse",
        // nd)`. They start at the first string literal past the position.
        let after_pos = &rest[rest.len().min(1)..];
        let split = after_pos
            .iter()
            .position(|a| matches!(a.kind, ExprKind::Str(_)))
            .unwrap_or(after_pos.len());
        let axis = self.axis_angle(&after_pos[..split], span);
        let reads = self.illuminance_params(&after_pos[split..]);
        self.in_illuminance += 1;
        self.varying_ctx += 1;
        let (b, ()) = self.with_block(|lw| {
            for read in &reads {
                lw.expr(read, None);
            }
            lw.scoped_stmt(body)
        });
        self.varying_ctx -= 1;
        self.in_illuminance -= 1;
        self.emit(Instr::Illuminance {
            category,
            pos: pos.reg,
            axis,
            body: b,
        });
    }

    /// The `"name", value` pairs of an illuminance loop. `"light:NAME", var` (PRMan's
    /// message passing from each light) becomes `lightsource("NAME", var)` at the top of the
    /// loop body, so `var` holds the current light's output parameter; the calls are
    /// returned for the body to lower. `"send:light:NAME", value` (a value handed to the
    /// light before it runs) is evaluated and not used, with a warning; `"lightcache"` needs
    /// nothing (arbor runs the lights afresh for every loop).
    fn illuminance_params(&mut self, args: &[Expr]) -> Vec<Expr> {
        let mut reads = Vec::new();
        let mut k = 0;
        while k < args.len() {
            let ExprKind::Str(name) = &args[k].kind else {
                self.expr(&args[k], None);
                self.diags.push(
                    Diag::error(
                        "sl::call",
                        "`illuminance` parameters come in \"name\", value pairs",
                    )
                    .label(args[k].span, "expected a parameter name"),
                );
                k += 1;
                continue;
            };
            let Some(value) = args.get(k + 1) else {
                self.diags.push(
                    Diag::error(
                        "sl::call",
                        format!("`illuminance` parameter \"{name}\" without a value"),
                    )
                    .label(args[k].span, "no value"),
                );
                break;
            };
            let light_param = name
                .strip_prefix("light:")
                .or_else(|| name.strip_prefix("lightsource:"));
            if let Some(param) = light_param {
                reads.push(Expr {
                    kind: ExprKind::Call {
                        name: "lightsource".to_string(),
                        name_span: args[k].span,
                        args: vec![
                            Expr {
                                kind: ExprKind::Str(param.to_string()),
                                span: args[k].span,
                            },
                            value.clone(),
                        ],
                    },
                    span: args[k].span.to(value.span),
                });
            } else {
                self.expr(value, None);
                // arbor runs the lights afresh for every loop, which is what
                // "lightcache" "refresh" asks for (and "reuse" gives the same light).
                if name == "lightcache" {
                    k += 2;
                    continue;
                }
                let what = if name.starts_with("send:light:") {
                    format!(
                        "`illuminance` sends \"{name}\" to the lights: arbor does not pass it; \
                         each light runs with its own parameter values"
                    )
                } else {
                    format!("`illuminance` parameter \"{name}\" is not used by arbor")
                };
                self.diags.push(
                    Diag::warning("sl::unsupported", what)
                        .label(args[k].span, "not used")
                        .help("\"light:NAME\", var reads a light's output parameter into var"),
                );
            }
            k += 2;
        }
        reads
    }

    fn lower_loop(
        &mut self,
        span: Span,
        init: Option<&Expr>,
        cond: Option<&Expr>,
        step: Option<&Expr>,
        body: &Stmt,
    ) {
        self.push_scope();
        if let Some(i) = init {
            self.expr(i, None);
        }
        let forced_varying = self.forced.contains(&span);
        let (cond_code, c) = self.with_block(|lw| match cond {
            Some(c) => lw.cond(c),
            None => lw.const_val(Const::F(1.0), BaseType::Float),
        });
        let varying = c.varying || forced_varying;
        if varying {
            self.varying_ctx += 1;
        }
        self.loops.push(LoopFrame {
            varying_ctx: self.varying_ctx,
            span,
        });
        let (b, ()) = self.with_block(|lw| lw.scoped_stmt(body));
        let (st, ()) = self.with_block(|lw| {
            if let Some(s) = step {
                lw.expr(s, None);
            }
        });
        self.loops.pop();
        if varying {
            self.varying_ctx -= 1;
        }
        self.pop_scope();
        self.emit(Instr::Loop {
            cond_code,
            cond: c.reg,
            body: b,
            step: st,
            span,
            compact: None,
        });
    }

    /// A condition: relations and logical operators (a float is accepted, as most compilers do).
    fn cond(&mut self, e: &Expr) -> Val {
        let v = self.expr(e, Some(BaseType::Float));
        if v.ty != BaseType::Float || v.array.is_some() {
            return self.error(
                Diag::error(
                    "sl::type",
                    format!(
                        "a condition must be a relation, found {}",
                        ty_name(v.ty, v.array)
                    ),
                )
                .label(e.span, "condition"),
            );
        }
        v
    }

    // ---- stores ----

    fn store(&mut self, var: &Var, v: Val, span: Span) {
        self.store_reg(var, var.reg, v, span)
    }

    fn store_reg(&mut self, var: &Var, reg: Reg, v: Val, span: Span) {
        if !var.varying && (v.varying || self.varying_ctx > var.decl_ctx) {
            if let Some(c) = var.candidate {
                self.newly_forced.insert(c);
                return;
            }
            let why = if v.varying {
                "a varying value"
            } else {
                "a value under varying control flow"
            };
            self.diags.push(
                Diag::error(
                    "sl::detail",
                    format!("cannot assign {why} to a uniform variable"),
                )
                .label(span, "assignment")
                .label(var.decl_span, "declared uniform here")
                .help("declare the variable `varying`"),
            );
            return;
        }
        self.emit(Instr::Mov {
            dst: reg,
            src: v.reg,
        });
    }

    fn mark_written(&mut self, reg: Reg) {
        for g in &mut self.globals {
            if g.reg == reg {
                g.written = true;
            }
        }
        self.mark_used(reg);
    }

    fn mark_used(&mut self, reg: Reg) {
        if (reg as usize) < self.globals_end {
            self.used_globals.insert(reg);
        }
    }

    // ---- expressions ----

    /// Converts a value to a type (float → triple/matrix promotion, triple ↔ triple retyping).
    fn coerce(&mut self, v: Val, to: BaseType, span: Span) -> Val {
        if v.reg == self.error_reg && v.ty == BaseType::Float && to != BaseType::Float {
            return Val {
                ty: to,
                ..self.error_val_of(to)
            };
        }
        if v.ty == to {
            return v;
        }
        if v.array.is_some() {
            return self.error(
                Diag::error("sl::type", format!("cannot use an array as {}", to.name()))
                    .label(span, "array"),
            );
        }
        match (v.ty, to) {
            (a, b) if a.is_triple() && b.is_triple() => Val { ty: b, ..v },
            (BaseType::Float, b) if b.is_triple() => {
                if let Some(Const::F(x)) = self.const_of(&v).cloned() {
                    return self.const_val(Const::T(Vec3::splat(x)), b);
                }
                let t = self.temp(b, v.varying);
                self.emit(Instr::Promote {
                    to: Kind::Triple,
                    dst: t.reg,
                    a: v.reg,
                });
                t
            }
            (BaseType::Float, BaseType::Matrix) => {
                if let Some(Const::F(x)) = self.const_of(&v).cloned() {
                    return self.const_val(Const::M(Mat4::IDENTITY * x), BaseType::Matrix);
                }
                let t = self.temp(BaseType::Matrix, v.varying);
                self.emit(Instr::Promote {
                    to: Kind::Matrix,
                    dst: t.reg,
                    a: v.reg,
                });
                t
            }
            (BaseType::Void, _) => self.error(
                Diag::error("sl::type", "a void function has no value")
                    .label(span, "used as a value"),
            ),
            (a, b) => self.error(
                Diag::error(
                    "sl::type",
                    format!("cannot convert {} to {}", a.name(), b.name()),
                )
                .label(span, format!("this is {}", a.name())),
            ),
        }
    }

    fn error_val_of(&mut self, ty: BaseType) -> Val {
        match Kind::of(ty) {
            Kind::Float => self.error_val(),
            Kind::Triple => self.const_val(Const::T(Vec3::ZERO), ty),
            Kind::Matrix => self.const_val(Const::M(Mat4::IDENTITY), ty),
            Kind::Str => self.const_val(Const::S(Arc::from("")), ty),
        }
    }

    fn expr(&mut self, e: &Expr, hint: Option<BaseType>) -> Val {
        match &e.kind {
            ExprKind::Float(x) => self.const_val(Const::F(*x), BaseType::Float),
            ExprKind::Str(s) => self.const_val(Const::S(Arc::from(s.as_str())), BaseType::String),
            ExprKind::Ident(name) => self.ident(name, e.span),
            ExprKind::Index { base, index } => {
                if let Some(get) = self.triple_component(base, index, e.span) {
                    return self.expr(&get, hint);
                }
                let Some((var, _)) = self.array_var(base) else {
                    return self.error(
                        Diag::error("sl::type", "only arrays can be indexed")
                            .label(base.span, "not an array"),
                    );
                };
                let n = var.array.unwrap_or(1);
                let idx = self.expr(index, Some(BaseType::Float));
                let idx = self.coerce(idx, BaseType::Float, index.span);
                if let Some(Const::F(i)) = self.const_of(&idx) {
                    let i = *i as i64;
                    if i < 0 || i >= n as i64 {
                        return self.error(
                            Diag::error(
                                "sl::array",
                                format!("index {i} is outside the array of {n}"),
                            )
                            .label(index.span, "index"),
                        );
                    }
                    return Val {
                        reg: var.reg + i as Reg,
                        ty: var.ty,
                        varying: var.varying,
                        array: None,
                    };
                }
                let t = self.temp(var.ty, var.varying || idx.varying);
                self.emit(Instr::GetIndex {
                    kind: Kind::of(var.ty),
                    dst: t.reg,
                    base: var.reg,
                    len: n as u32,
                    index: idx.reg,
                    span: e.span,
                });
                t
            }
            ExprKind::Call {
                name,
                name_span,
                args,
            } => self.call(name, *name_span, args, e.span, hint),
            ExprKind::Tuple(items) => self.tuple(items, e.span, hint),
            ExprKind::ArrayLit(_) => self.error(
                Diag::error("sl::array", "{…} initialises arrays only")
                    .label(e.span, "not in an array declaration"),
            ),
            ExprKind::Cast { ty, space, expr } => self.cast(*ty, space.as_deref(), expr, e.span),
            ExprKind::Unary { op, expr } => {
                let v = self.expr(expr, hint);
                match op {
                    UnOp::Plus => v,
                    UnOp::Neg => {
                        if v.ty == BaseType::String || v.array.is_some() {
                            return self.error(
                                Diag::error(
                                    "sl::type",
                                    format!("cannot negate {}", ty_name(v.ty, v.array)),
                                )
                                .label(e.span, "here"),
                            );
                        }
                        match self.const_of(&v).cloned() {
                            Some(Const::F(x)) => return self.const_val(Const::F(-x), v.ty),
                            Some(Const::T(x)) => return self.const_val(Const::T(-x), v.ty),
                            _ => {}
                        }
                        let t = self.temp(v.ty, v.varying);
                        self.emit(Instr::Neg {
                            kind: Kind::of(v.ty),
                            dst: t.reg,
                            a: v.reg,
                        });
                        t
                    }
                    UnOp::Not => {
                        let v = self.coerce(v, BaseType::Float, expr.span);
                        let t = self.temp(BaseType::Float, v.varying);
                        self.emit(Instr::Not {
                            dst: t.reg,
                            a: v.reg,
                        });
                        t
                    }
                }
            }
            ExprKind::Binary { op, lhs, rhs } => self.binary(*op, lhs, rhs, e.span, hint),
            ExprKind::Ternary {
                cond,
                then,
                otherwise,
            } => {
                let c = self.cond(cond);
                let a = self.expr(then, hint);
                let b = self.expr(otherwise, hint.or(Some(a.ty)));
                let ty = self.unify(a.ty, b.ty, e.span);
                let a = self.coerce(a, ty, then.span);
                let b = self.coerce(b, ty, otherwise.span);
                let t = self.temp(ty, c.varying || a.varying || b.varying);
                self.emit(Instr::Select {
                    kind: Kind::of(ty),
                    dst: t.reg,
                    cond: c.reg,
                    a: a.reg,
                    b: b.reg,
                });
                t
            }
            ExprKind::Assign { op, target, value } => self.assign(*op, target, value, e.span),
        }
    }

    fn ident(&mut self, name: &str, span: Span) -> Val {
        match self.lookup(name) {
            Some(var) => {
                self.mark_used(var.reg);
                if GLOBALS.iter().any(|g| g.0 == name)
                    && self.scopes[0].get(name).map(|g| g.reg) == Some(var.reg)
                {
                    if name == "I" && self.kind == ShaderKind::Light {
                        self.warn_extension(
                            "I",
                            span,
                            "`I` in a light shader is a PRMan extension; arbor gives the illuminated surface's incident vector",
                        );
                    }
                    if matches!(name, "L" | "Cl" | "Ol")
                        && matches!(self.kind, ShaderKind::Surface | ShaderKind::Volume)
                        && self.in_illuminance == 0
                    {
                        self.diags.push(
                            Diag::error(
                                "sl::context",
                                format!("`{name}` is only defined inside `illuminance`"),
                            )
                            .label(span, "used here"),
                        );
                    }
                }
                Val {
                    reg: var.reg,
                    ty: var.ty,
                    varying: var.varying,
                    array: var.array,
                }
            }
            None if name == "PI" => self.const_val(Const::F(std::f32::consts::PI), BaseType::Float),
            None if name == "Ns" && self.kind == ShaderKind::Light => {
                // PRMan's `Ns`: the normal at the illuminated point, which is what arbor
                // binds to `N` in light shaders.
                self.warn_extension(
                    "Ns",
                    span,
                    "`Ns` is a PRMan extension; arbor reads the illuminated surface's normal `N`",
                );
                self.ident("N", span)
            }
            None if name == "Ps"
                && matches!(self.kind, ShaderKind::Surface | ShaderKind::Displacement) =>
            {
                // `Ps` is the light shader's name for the point being lit; published surface
                // shaders (the RenderMan Companion's `windowhighlight`) use it for that point,
                // which in a surface shader is `P`.
                self.warn_extension(
                    "Ps",
                    span,
                    "`Ps` is a light-shader variable (the point being lit); in a surface shader arbor reads `P`",
                );
                self.ident("P", span)
            }
            None if self.kind == ShaderKind::Imager && matches!(name, "s" | "t") => {
                // RISpec gives imagers no surface parameters, but Aqsis binds s and t to the
                // pixel's raster position (its centre, x + 0.5 and y + 0.5): its `filmgrain`
                // imager calls noise(s, t) for a grain that changes from pixel to pixel. That
                // is arbor's imager `P` (the pixel centre in raster space), read by component.
                let (key, comp): (&'static str, &str) = if name == "s" {
                    ("s", "xcomp")
                } else {
                    ("t", "ycomp")
                };
                self.warn_extension(
                    key,
                    span,
                    &format!(
                        "`{name}` is not defined in imager shaders (RISpec); arbor reads the \
                         pixel's raster {} (`{comp}(P)`), as Aqsis does",
                        if name == "s" { "x" } else { "y" }
                    ),
                );
                let call = Expr {
                    kind: ExprKind::Call {
                        name: comp.into(),
                        name_span: span,
                        args: vec![Expr {
                            kind: ExprKind::Ident("P".into()),
                            span,
                        }],
                    },
                    span,
                };
                self.expr(&call, Some(BaseType::Float))
            }
            None if self.kind == ShaderKind::Imager && matches!(name, "u" | "v" | "du" | "dv") => {
                // No renderer defines these for imagers (Aqsis binds only s and t).
                let what: &'static str = match name {
                    "u" => "u",
                    "v" => "v",
                    "du" => "du",
                    _ => "dv",
                };
                self.warn_extension(
                    what,
                    span,
                    &format!("`{name}` is not defined in imager shaders (RISpec); it reads 0 here"),
                );
                self.const_val(Const::F(0.0), BaseType::Float)
            }
            None => {
                let is_global = GLOBALS.iter().any(|g| g.0 == name);
                let mut d = if is_global {
                    Diag::error(
                        "sl::context",
                        format!("`{name}` is not available in {} shaders", self.kind.name()),
                    )
                    .label(span, "not available here")
                } else {
                    Diag::error("sl::name", format!("unknown variable `{name}`"))
                        .label(span, "not declared")
                };
                let names: Vec<String> =
                    self.scopes.iter().flat_map(|s| s.keys().cloned()).collect();
                if let Some(m) = did_you_mean(name, names.iter().map(String::as_str)) {
                    d = d.help(format!("did you mean `{m}`?"));
                }
                self.error(d)
            }
        }
    }

    /// `c[i]` with `c` a colour, point, vector or normal variable (not an array): PRMan's
    /// (and 3Delight's) component access, the same as `comp(c, i)`, which is returned.
    fn triple_component(&mut self, base: &Expr, index: &Expr, span: Span) -> Option<Expr> {
        let ExprKind::Ident(n) = &base.kind else {
            return None;
        };
        let v = self.lookup(n)?;
        if v.array.is_some() || !v.ty.is_triple() {
            return None;
        }
        Some(Expr {
            kind: ExprKind::Call {
                name: "comp".into(),
                name_span: span,
                args: vec![base.clone(), index.clone()],
            },
            span,
        })
    }

    fn array_var(&mut self, e: &Expr) -> Option<(Var, Span)> {
        if let ExprKind::Ident(n) = &e.kind {
            let v = self.lookup(n)?;
            if v.array.is_some() {
                return Some((v, e.span));
            }
        }
        None
    }

    fn unify(&mut self, a: BaseType, b: BaseType, span: Span) -> BaseType {
        if a == b {
            return a;
        }
        match (a, b) {
            (BaseType::Float, t) | (t, BaseType::Float)
                if t.is_triple() || t == BaseType::Matrix =>
            {
                t
            }
            (x, y) if x.is_triple() && y.is_triple() => {
                if x == BaseType::Point || y == BaseType::Point {
                    BaseType::Point
                } else if x == BaseType::Color || y == BaseType::Color {
                    BaseType::Color
                } else {
                    BaseType::Vector
                }
            }
            _ => {
                self.diags.push(
                    Diag::error(
                        "sl::type",
                        format!("{} and {} do not mix", a.name(), b.name()),
                    )
                    .label(span, "here"),
                );
                a
            }
        }
    }

    fn tuple(&mut self, items: &[Expr], span: Span, hint: Option<BaseType>) -> Val {
        match items.len() {
            3 => {
                let ty = match hint {
                    Some(t) if t.is_triple() => t,
                    _ => BaseType::Point,
                };
                let vals: Vec<Val> = items
                    .iter()
                    .map(|i| {
                        let v = self.expr(i, Some(BaseType::Float));
                        self.coerce(v, BaseType::Float, i.span)
                    })
                    .collect();
                let consts: Option<Vec<f32>> = vals
                    .iter()
                    .map(|v| match self.const_of(v) {
                        Some(Const::F(x)) => Some(*x),
                        _ => None,
                    })
                    .collect();
                if let Some(c) = consts {
                    return self.const_val(Const::T(Vec3::new(c[0], c[1], c[2])), ty);
                }
                let t = self.temp(ty, vals.iter().any(|v| v.varying));
                self.emit(Instr::MakeTriple {
                    dst: t.reg,
                    x: vals[0].reg,
                    y: vals[1].reg,
                    z: vals[2].reg,
                });
                t
            }
            16 => {
                let vals: Vec<Val> = items
                    .iter()
                    .map(|i| {
                        let v = self.expr(i, Some(BaseType::Float));
                        self.coerce(v, BaseType::Float, i.span)
                    })
                    .collect();
                let consts: Option<Vec<f32>> = vals
                    .iter()
                    .map(|v| match self.const_of(v) {
                        Some(Const::F(x)) => Some(*x),
                        _ => None,
                    })
                    .collect();
                if let Some(c) = consts {
                    let mut a = [0f32; 16];
                    a.copy_from_slice(&c);
                    return self.const_val(Const::M(Mat4::from_cols_array(&a)), BaseType::Matrix);
                }
                let mut regs = [0 as Reg; 16];
                for (i, v) in vals.iter().enumerate() {
                    regs[i] = v.reg;
                }
                let t = self.temp(BaseType::Matrix, vals.iter().any(|v| v.varying));
                self.emit(Instr::MakeMatrix {
                    dst: t.reg,
                    elems: Box::new(regs),
                });
                t
            }
            1 => self.expr(&items[0], hint),
            n => self.error(
                Diag::error(
                    "sl::type",
                    format!("a tuple of {n} values is neither a triple nor a matrix"),
                )
                .label(span, "tuple")
                .help("write 3 values for a point/vector/normal/color, 16 for a matrix"),
            ),
        }
    }

    fn cast(&mut self, ty: BaseType, space: Option<&str>, expr: &Expr, span: Span) -> Val {
        let v = self.expr(expr, Some(ty));
        if ty == BaseType::Float || ty == BaseType::String {
            if space.is_some() {
                self.diags.push(
                    Diag::error("sl::type", format!("{} takes no space name", ty.name()))
                        .label(span, "here"),
                );
            }
            return self.coerce(v, ty, expr.span);
        }
        let v = self.coerce(v, ty, expr.span);
        let Some(space) = space else { return v };
        let sp = self.const_val(Const::S(Arc::from(space)), BaseType::String);
        match ty {
            BaseType::Color => {
                if space == "rgb" {
                    return v;
                }
                if !matches!(space, "hsv" | "hsl" | "xyz" | "XYZ" | "xyY" | "YIQ") {
                    self.diags.push(
                        Diag::error("sl::color", format!("unknown colour space \"{space}\""))
                            .label(span, "here")
                            .help("colour spaces are rgb, hsv, hsl, xyz, xyY and YIQ"),
                    );
                }
                let t = self.temp(ty, v.varying);
                self.emit(Instr::ColorFrom {
                    dst: t.reg,
                    space: sp.reg,
                    a: v.reg,
                    span,
                });
                t
            }
            BaseType::Matrix => {
                let m = self.temp(BaseType::Matrix, false);
                self.emit(Instr::SpaceMatrix {
                    dst: m.reg,
                    space: sp.reg,
                    span,
                });
                let t = self.temp(ty, v.varying);
                // RSL row-vector product v * m  ==  glam m * v
                self.emit(Instr::Arith {
                    op: Arith::Mul,
                    kind: Kind::Matrix,
                    dst: t.reg,
                    a: v.reg,
                    b: m.reg,
                    span,
                });
                t
            }
            _ => {
                if space == "current" {
                    return v;
                }
                let kind = match ty {
                    BaseType::Point => XformKind::Point,
                    BaseType::Vector => XformKind::Vector,
                    _ => XformKind::Normal,
                };
                let t = self.temp(ty, v.varying);
                self.emit(Instr::Transform {
                    kind,
                    dst: t.reg,
                    from: Space::Named(sp.reg),
                    to: Space::Current,
                    a: v.reg,
                    span,
                });
                t
            }
        }
    }

    fn binary(
        &mut self,
        op: BinOp,
        lhs: &Expr,
        rhs: &Expr,
        span: Span,
        hint: Option<BaseType>,
    ) -> Val {
        // The context's type does not reach into arithmetic: a call whose return type is
        // ambiguous (`noise`, `texture`, …) inside `c *= 1 - k + k * noise(x)` is a float
        // unless its sibling operand says otherwise, as PRMan and Aqsis compile it (a colour
        // hint there gave LGParquetPlank's planks a different noise per channel).
        let _ = hint;
        let sub_hint = match op {
            BinOp::Dot | BinOp::Cross => Some(BaseType::Vector),
            _ => None,
        };
        let a = self.expr(lhs, sub_hint);
        // A float sibling asks for nothing a missing hint does not (ambiguous calls default
        // to float), except of trace(), which RISpec only has as a colour.
        let b = self.expr(
            rhs,
            sub_hint.or(Some(a.ty).filter(|t| *t != BaseType::Float)),
        );
        if a.array.is_some() || b.array.is_some() {
            return self.error(
                Diag::error(
                    "sl::type",
                    format!("operator `{}` does not work on arrays", op.symbol()),
                )
                .label(span, "here"),
            );
        }
        let varying = a.varying || b.varying;
        match op {
            BinOp::And | BinOp::Or => {
                let a = self.coerce(a, BaseType::Float, lhs.span);
                let b = self.coerce(b, BaseType::Float, rhs.span);
                let t = self.temp(BaseType::Float, varying);
                self.emit(if op == BinOp::And {
                    Instr::And {
                        dst: t.reg,
                        a: a.reg,
                        b: b.reg,
                    }
                } else {
                    Instr::Or {
                        dst: t.reg,
                        a: a.reg,
                        b: b.reg,
                    }
                });
                t
            }
            BinOp::Eq | BinOp::Ne | BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge => {
                let cmp = match op {
                    BinOp::Eq => Cmp::Eq,
                    BinOp::Ne => Cmp::Ne,
                    BinOp::Lt => Cmp::Lt,
                    BinOp::Le => Cmp::Le,
                    BinOp::Gt => Cmp::Gt,
                    _ => Cmp::Ge,
                };
                let ty = if a.ty == BaseType::String || b.ty == BaseType::String {
                    if a.ty != b.ty {
                        return self.error(
                            Diag::error("sl::type", "a string can only be compared with a string")
                                .label(span, "comparison"),
                        );
                    }
                    BaseType::String
                } else {
                    self.unify(a.ty, b.ty, span)
                };
                if !matches!(cmp, Cmp::Eq | Cmp::Ne) && ty != BaseType::Float {
                    return self.error(
                        Diag::error(
                            "sl::type",
                            format!("`{}` compares floats only, not {}", op.symbol(), ty.name()),
                        )
                        .label(span, "comparison"),
                    );
                }
                let a = self.coerce(a, ty, lhs.span);
                let b = self.coerce(b, ty, rhs.span);
                let t = self.temp(BaseType::Float, varying);
                self.emit(Instr::Compare {
                    op: cmp,
                    kind: Kind::of(ty),
                    dst: t.reg,
                    a: a.reg,
                    b: b.reg,
                });
                t
            }
            BinOp::Dot => {
                if !a.ty.is_triple() || !b.ty.is_triple() {
                    return self.error(
                        Diag::error(
                            "sl::type",
                            format!(
                                "`.` (dot product) needs two triples, found {} and {}",
                                a.ty.name(),
                                b.ty.name()
                            ),
                        )
                        .label(span, "here"),
                    );
                }
                let t = self.temp(BaseType::Float, varying);
                self.emit(Instr::Dot {
                    dst: t.reg,
                    a: a.reg,
                    b: b.reg,
                });
                t
            }
            BinOp::Cross => {
                if !a.ty.is_triple() || !b.ty.is_triple() {
                    return self.error(
                        Diag::error(
                            "sl::type",
                            format!(
                                "`^` (cross product) needs two triples, found {} and {}",
                                a.ty.name(),
                                b.ty.name()
                            ),
                        )
                        .label(span, "here"),
                    );
                }
                let ty = if a.ty == BaseType::Color {
                    BaseType::Color
                } else {
                    BaseType::Vector
                };
                let t = self.temp(ty, varying);
                self.emit(Instr::Cross {
                    dst: t.reg,
                    a: a.reg,
                    b: b.reg,
                });
                t
            }
            BinOp::Add | BinOp::Sub | BinOp::Mul | BinOp::Div => {
                if a.ty == BaseType::String || b.ty == BaseType::String {
                    return self.error(
                        Diag::error(
                            "sl::type",
                            format!("operator `{}` does not work on strings", op.symbol()),
                        )
                        .label(span, "here"),
                    );
                }
                let arith = match op {
                    BinOp::Add => Arith::Add,
                    BinOp::Sub => Arith::Sub,
                    BinOp::Mul => Arith::Mul,
                    _ => Arith::Div,
                };
                // matrix * point etc. is not an operator in RSL (use transform()).
                if (a.ty == BaseType::Matrix) != (b.ty == BaseType::Matrix)
                    && a.ty != BaseType::Float
                    && b.ty != BaseType::Float
                {
                    return self.error(
                        Diag::error(
                            "sl::type",
                            format!(
                                "cannot {} a {} and a {}",
                                op.symbol(),
                                a.ty.name(),
                                b.ty.name()
                            ),
                        )
                        .label(span, "here")
                        .help("use transform(m, p) to transform a point by a matrix"),
                    );
                }
                let mut ty = self.unify(a.ty, b.ty, span);
                if op == BinOp::Sub && a.ty == BaseType::Point && b.ty == BaseType::Point {
                    ty = BaseType::Vector;
                }
                let a = self.coerce(a, ty, lhs.span);
                let b = self.coerce(b, ty, rhs.span);
                // constant folding
                match (self.const_of(&a).cloned(), self.const_of(&b).cloned()) {
                    (Some(Const::F(x)), Some(Const::F(y))) => {
                        let r = match arith {
                            Arith::Add => x + y,
                            Arith::Sub => x - y,
                            Arith::Mul => x * y,
                            Arith::Div => {
                                if y == 0.0 {
                                    0.0
                                } else {
                                    x / y
                                }
                            }
                        };
                        return self.const_val(Const::F(r), ty);
                    }
                    (Some(Const::T(x)), Some(Const::T(y))) if arith != Arith::Div => {
                        let r = match arith {
                            Arith::Add => x + y,
                            Arith::Sub => x - y,
                            _ => x * y,
                        };
                        return self.const_val(Const::T(r), ty);
                    }
                    _ => {}
                }
                let t = self.temp(ty, varying);
                self.emit(Instr::Arith {
                    op: arith,
                    kind: Kind::of(ty),
                    dst: t.reg,
                    a: a.reg,
                    b: b.reg,
                    span,
                });
                t
            }
        }
    }

    fn assign(&mut self, op: AssignOp, target: &Expr, value: &Expr, span: Span) -> Val {
        match &target.kind {
            ExprKind::Ident(name) => {
                let Some(var) = self.lookup(name) else {
                    return self.ident(name, target.span);
                };
                // BMRT's and PRMan's light shaders may overwrite their geometric inputs (e.g.
                // `N = normalize(N)` in arealight.sl); arbor keeps the change local to the light.
                let light_local: Option<&'static str> = match name.as_str() {
                    "N" => Some("N"),
                    "Ng" => Some("Ng"),
                    "P" => Some("P"),
                    "s" => Some("s"),
                    "t" => Some("t"),
                    "u" => Some("u"),
                    "v" => Some("v"),
                    _ => None,
                };
                let is_global = self.scopes[0].get(name.as_str()).map(|g| g.reg) == Some(var.reg);
                // PRMan lets a surface or volume shader scale the light it is looking at inside
                // `illuminance` (Pixar's own Slim templates do `Cl *= 1 - nonspec`); the value
                // is the current light's and is set afresh for the next one.
                let per_light = matches!(name.as_str(), "Cl" | "L")
                    && matches!(self.kind, ShaderKind::Surface | ShaderKind::Volume)
                    && self.in_illuminance > 0;
                let var = match light_local {
                    _ if per_light && !var.writable && is_global => {
                        self.warn_extension(
                            if name == "Cl" { "illuminance-Cl" } else { "illuminance-L" },
                            target.span,
                            &format!("assigning `{name}` inside `illuminance` is a PRMan extension; the new value holds for this light only"),
                        );
                        Var {
                            writable: true,
                            ..var
                        }
                    }
                    Some(key) if !var.writable && is_global && self.kind == ShaderKind::Light => {
                        self.warn_extension(
                            key,
                            target.span,
                            &format!("assigning `{name}` in a light shader is an extension of BMRT and PRMan; the new value stays local to this light"),
                        );
                        Var {
                            writable: true,
                            ..var
                        }
                    }
                    _ => var,
                };
                if !var.writable {
                    return self.error(
                        Diag::error("sl::readonly", format!("`{name}` cannot be assigned here"))
                            .label(target.span, "read-only")
                            .help(if GLOBALS.iter().any(|g| g.0 == name) {
                                format!("{} shaders may only read `{name}`", self.kind.name())
                            } else {
                                "function parameters are read-only unless declared `output`"
                                    .to_string()
                            }),
                    );
                }
                if var.array.is_some() {
                    return self.error(
                        Diag::error("sl::array", "arrays cannot be assigned as a whole")
                            .label(span, "assignment"),
                    );
                }
                let saved = self.uniform_target;
                self.uniform_target = self.is_uniform_target(&var);
                let v = self.assign_value(op, &var_val(&var), value, span);
                self.uniform_target = saved;
                let v = self.coerce(v, var.ty, value.span);
                self.store(&var, v, span);
                self.mark_written(var.reg);
                Val {
                    reg: var.reg,
                    ty: var.ty,
                    varying: var.varying,
                    array: None,
                }
            }
            ExprKind::Index { base, index } => {
                if let Some(get) = self.triple_component(base, index, target.span) {
                    // `c[i] op= v` is `setcomp(c, i, comp(c, i) op v)`; its value is the new
                    // component.
                    let new = match compound_op(op) {
                        None => value.clone(),
                        Some(op) => Expr {
                            kind: ExprKind::Binary {
                                op,
                                lhs: Box::new(get.clone()),
                                rhs: Box::new(value.clone()),
                            },
                            span,
                        },
                    };
                    let set = Expr {
                        kind: ExprKind::Call {
                            name: "setcomp".into(),
                            name_span: target.span,
                            args: vec![(**base).clone(), (**index).clone(), new],
                        },
                        span,
                    };
                    self.expr(&set, None);
                    return self.expr(&get, None);
                }
                let Some((var, _)) = self.array_var(base) else {
                    return self.error(
                        Diag::error("sl::type", "only arrays can be indexed")
                            .label(base.span, "not an array"),
                    );
                };
                if !var.writable {
                    return self.error(
                        Diag::error("sl::readonly", "this array cannot be assigned here")
                            .label(target.span, "read-only"),
                    );
                }
                let n = var.array.unwrap_or(1);
                let idx = self.expr(index, Some(BaseType::Float));
                let idx = self.coerce(idx, BaseType::Float, index.span);
                let current = self.expr(target, Some(var.ty));
                let v = self.assign_value(op, &current, value, span);
                let v = self.coerce(v, var.ty, value.span);
                if let Some(Const::F(i)) = self.const_of(&idx).cloned() {
                    let i = i as i64;
                    if i < 0 || i >= n as i64 {
                        return self.error(
                            Diag::error(
                                "sl::array",
                                format!("index {i} is outside the array of {n}"),
                            )
                            .label(index.span, "index"),
                        );
                    }
                    self.store_reg(&var, var.reg + i as Reg, v, span);
                } else {
                    if !var.varying && (v.varying || idx.varying || self.varying_ctx > var.decl_ctx)
                    {
                        if let Some(c) = var.candidate {
                            self.newly_forced.insert(c);
                            return v;
                        }
                        return self.error(
                            Diag::error(
                                "sl::detail",
                                "cannot assign a varying value to a uniform array",
                            )
                            .label(span, "assignment")
                            .label(var.decl_span, "declared uniform here"),
                        );
                    }
                    self.emit(Instr::SetIndex {
                        kind: Kind::of(var.ty),
                        base: var.reg,
                        len: n as u32,
                        index: idx.reg,
                        src: v.reg,
                        span,
                    });
                }
                v
            }
            _ => self.error(
                Diag::error(
                    "sl::assign",
                    "only a variable or an array element can be assigned",
                )
                .label(target.span, "not assignable"),
            ),
        }
    }

    fn assign_value(&mut self, op: AssignOp, current: &Val, value: &Expr, span: Span) -> Val {
        let Some(bop) = compound_op(op) else {
            return self.expr(value, Some(current.ty));
        };
        let rhs = self.expr(value, Some(current.ty));
        self.binary_vals(bop, *current, rhs, span)
    }

    /// Arithmetic on already-lowered values (for compound assignment).
    fn binary_vals(&mut self, op: BinOp, a: Val, b: Val, span: Span) -> Val {
        let ty = self.unify(a.ty, b.ty, span);
        let a = self.coerce(a, ty, span);
        let b = self.coerce(b, ty, span);
        let arith = match op {
            BinOp::Add => Arith::Add,
            BinOp::Sub => Arith::Sub,
            BinOp::Mul => Arith::Mul,
            _ => Arith::Div,
        };
        let t = self.temp(ty, a.varying || b.varying);
        self.emit(Instr::Arith {
            op: arith,
            kind: Kind::of(ty),
            dst: t.reg,
            a: a.reg,
            b: b.reg,
            span,
        });
        t
    }

    // ---- calls ----

    fn call(
        &mut self,
        name: &str,
        name_span: Span,
        args: &[Expr],
        span: Span,
        hint: Option<BaseType>,
    ) -> Val {
        if let Some(entries) = self.lookup_funcs(name) {
            return self.user_call(name, entries, args, span, hint);
        }
        match name {
            "texture" | "environment" | "shadow" | "bump" => {
                return self.texture_call(name, args, span, hint)
            }
            "transform" | "vtransform" | "ntransform" => {
                return self.transform_call(name, args, span)
            }
            "filterstep" => return self.filterstep(args, span),
            // PRMan's `trace(P, R, "bias", b, "samples", n, …)`: the ray itself is traced.
            "trace" if args.len() > 2 && self.is_string_expr(&args[2]) => {
                self.unused_ray_params("trace", args, 2, &["label"]);
                return self.call(name, name_span, &args[..2], span, hint);
            }
            // PRMan's `area(P, "dicing")` names how to measure; the area is the
            // micropolygon's in current space, as `area(P)`.
            "area" if args.len() == 2 && self.is_string_expr(&args[1]) => {
                let m = self.expr(&args[1], Some(BaseType::String));
                let _ = self.coerce(m, BaseType::String, args[1].span);
                self.warn_extension(
                    "area-measure",
                    args[1].span,
                    "`area(P, measure)` (PRMan): the measure is ignored and the area of the micropolygon around P in current space is returned, as `area(P)`",
                );
                return self.call(name, name_span, &args[..1], span, hint);
            }
            "printf" | "format" => return self.printf(name, args, span),
            "atmosphere" | "displacement" | "lightsource" | "surface" | "incident" | "opposite"
            | "attribute" | "option" | "rendererinfo" | "textureinfo" | "rayinfo" => {
                return self.message(name, args, span)
            }
            "occlusion" | "indirectdiffuse" | "transmission" | "visibility" => {
                return self.ray_call(name, args, span)
            }
            "shadername" => {
                let mut regs = Vec::new();
                for a in args {
                    let v = self.expr(a, Some(BaseType::String));
                    let v = self.coerce(v, BaseType::String, a.span);
                    regs.push(v.reg);
                }
                let t = self.temp(BaseType::String, false);
                self.emit(Instr::Call {
                    f: Builtin::ShaderName,
                    dst: t.reg,
                    args: regs,
                    span,
                });
                return t;
            }
            "arraylength" => {
                return match args.first().and_then(|a| self.array_var(a)) {
                    Some((v, _)) => {
                        self.const_val(Const::F(v.array.unwrap_or(1) as f32), BaseType::Float)
                    }
                    None => self.error(
                        Diag::error("sl::call", "`arraylength` takes an array variable")
                            .label(span, "here"),
                    ),
                };
            }
            "spline" => {
                if let Some(v) = self.spline_array(args, span, hint) {
                    return v;
                }
            }
            _ => {}
        }
        if let Some(v) = self.extension_call(name, args, span) {
            return v;
        }
        let sigs: Vec<&'static Sig> = builtins::overloads(name).collect();
        if sigs.is_empty() {
            let mut candidates: Vec<String> =
                builtins::SIGS.iter().map(|s| s.name.to_string()).collect();
            candidates.extend(builtins::SPECIAL.iter().map(|s| s.to_string()));
            for s in &self.funcs {
                candidates.extend(s.keys().cloned());
            }
            for a in args {
                self.expr(a, None);
            }
            if let Some(m) = did_you_mean(name, candidates.iter().map(String::as_str)) {
                let d = Diag::error("sl::name", format!("unknown function `{name}`"))
                    .label(name_span, "not defined")
                    .help(format!("did you mean `{m}`?"));
                return self.error(d);
            }
            return self.dso_shadeop(name, name_span, hint);
        }
        // Lower arguments once, with a hint when every overload agrees on the code.
        let mut vals = Vec::new();
        for (i, a) in args.iter().enumerate() {
            let codes: HashSet<char> = sigs
                .iter()
                .filter_map(|s| {
                    let (list, rep) = builtins::parse_args(s.args);
                    list.get(i)
                        .or(if rep { list.last() } else { None })
                        .map(|c| c.0)
                })
                .collect();
            let h = if codes.len() == 1 {
                codes.into_iter().next().and_then(builtins::code_type)
            } else {
                None
            };
            let is_out = sigs.iter().any(|s| {
                let (list, _) = builtins::parse_args(s.args);
                list.get(i).map(|c| c.1).unwrap_or(false)
            });
            if is_out {
                vals.push((self.expr(a, h), Some(a)));
            } else {
                vals.push((self.expr(a, h), Some(a)));
            }
        }
        // Pick the best overload.
        let mut best: Option<(u32, &'static Sig, Option<BaseType>)> = None;
        for s in &sigs {
            if let Some((score, tvar)) = self.score(s, &vals, hint) {
                if best.map_or(true, |b| score < b.0) {
                    best = Some((score, s, tvar));
                }
            }
        }
        let Some((_, sig, tvar)) = best else {
            let found: Vec<String> = vals.iter().map(|(v, _)| ty_name(v.ty, v.array)).collect();
            let forms: Vec<String> = sigs.iter().map(|s| sig_text(s)).collect();
            return self.error(
                Diag::error(
                    "sl::call",
                    format!("no form of `{name}` takes ({})", found.join(", ")),
                )
                .label(span, "call")
                .help(format!("`{name}` takes {}", forms.join(" or "))),
            );
        };
        let (codes, _) = builtins::parse_args(sig.args);
        let mut regs = Vec::new();
        let mut outs = Vec::new();
        let mut varying = always_varying(sig.f)
            && !(self.uniform_target && matches!(sig.f, Builtin::RandomF | Builtin::RandomT));
        if matches!(sig.f, Builtin::Horizon | Builtin::HorizonHeight) {
            // They read the surface frame (P, N, I) from the grid even when the shader
            // never names those globals: keep them in the program.
            for g in ["P", "N", "Ng", "I"] {
                if let Some(v) = self.lookup(g) {
                    self.mark_used(v.reg);
                }
            }
        }
        if sig.f == Builtin::FaceForward2 {
            // faceforward(N, I) judges the side by Ng, named or not.
            if let Some(v) = self.lookup("Ng") {
                self.mark_used(v.reg);
                // Its result varies with Ng; a uniform target keeps it uniform, as random().
                varying |= self.regs[v.reg as usize].varying && !self.uniform_target;
            }
        }
        for (i, (v, e)) in vals.iter().enumerate() {
            let (code, out) = codes
                .get(i)
                .copied()
                .unwrap_or_else(|| *codes.last().expect("repeat code"));
            let want = resolve_code(code, tvar).unwrap_or(v.ty);
            let sp = e.map(|e| e.span).unwrap_or(span);
            if out {
                // Output: a temporary holding the current value, stored back after the call.
                let cur = self.coerce(*v, want, sp);
                let t = self.temp(want, true);
                self.emit(Instr::Copy {
                    dst: t.reg,
                    src: cur.reg,
                });
                regs.push(t.reg);
                outs.push((t, *e));
            } else {
                let c = self.coerce(*v, want, sp);
                varying |= c.varying;
                regs.push(c.reg);
            }
        }
        let ret_ty = resolve_code(sig.ret, tvar).unwrap_or(BaseType::Float);
        // Output temporaries are varying when any input is.
        for (t, _) in &outs {
            self.regs[t.reg as usize].varying = varying;
        }
        let dst = self.temp(ret_ty, varying);
        self.emit(Instr::Call {
            f: sig.f,
            dst: dst.reg,
            args: regs,
            span,
        });
        for (t, e) in outs {
            if let Some(e) = e {
                let tv = Val { varying, ..t };
                self.store_back(e, tv);
            }
        }
        dst
    }

    /// Stores an output argument's value back into the lvalue it came from.
    fn store_back(&mut self, target: &Expr, v: Val) {
        match &target.kind {
            ExprKind::Ident(name) => match self.lookup(name) {
                Some(var) if var.writable => {
                    let v = self.coerce(v, var.ty, target.span);
                    self.store(&var, v, target.span);
                    self.mark_written(var.reg);
                }
                _ => {
                    self.diags.push(
                        Diag::error(
                            "sl::readonly",
                            format!("output argument `{name}` is not writable"),
                        )
                        .label(target.span, "output argument"),
                    );
                }
            },
            ExprKind::Index { base, index } => {
                if let Some((var, _)) = self.array_var(base) {
                    let idx = self.expr(index, Some(BaseType::Float));
                    if let Some(Const::F(i)) = self.const_of(&idx).cloned() {
                        if (i as usize) < var.array.unwrap_or(1) {
                            self.store_reg(&var, var.reg + i as Reg, v, target.span);
                            return;
                        }
                    }
                    self.emit(Instr::SetIndex {
                        kind: Kind::of(var.ty),
                        base: var.reg,
                        len: var.array.unwrap_or(1) as u32,
                        index: idx.reg,
                        src: v.reg,
                        span: target.span,
                    });
                }
            }
            _ => self.diags.push(
                Diag::error("sl::call", "an output argument must be a variable")
                    .label(target.span, "not a variable"),
            ),
        }
    }

    fn score(
        &self,
        s: &Sig,
        vals: &[(Val, Option<&Expr>)],
        hint: Option<BaseType>,
    ) -> Option<(u32, Option<BaseType>)> {
        let (codes, repeat) = builtins::parse_args(s.args);
        if vals.len() < codes.len() || (!repeat && vals.len() != codes.len()) {
            return None;
        }
        // Resolve the type variable from the first t/q argument that is a triple.
        let mut tvar: Option<BaseType> = None;
        for (i, (v, _)) in vals.iter().enumerate() {
            let (c, _) = codes
                .get(i)
                .copied()
                .unwrap_or_else(|| *codes.last().unwrap());
            if (c == 't' || c == 'q') && v.ty.is_triple() && tvar.is_none() {
                tvar = Some(v.ty);
            }
        }
        if tvar.is_none() && (s.ret == 't' || s.ret == 'q') {
            tvar = match hint {
                Some(h) if h.is_triple() => Some(h),
                _ => None,
            };
        }
        let mut score = 0u32;
        for (i, (v, _)) in vals.iter().enumerate() {
            if v.array.is_some() {
                return None;
            }
            let (c, out) = codes
                .get(i)
                .copied()
                .unwrap_or_else(|| *codes.last().unwrap());
            match c {
                't' | 'q' => {
                    if v.ty.is_triple() {
                        if Some(v.ty) != tvar {
                            score += 1;
                        }
                        if c == 'q' && v.ty == BaseType::Color {
                            score += 3;
                        }
                    } else if v.ty == BaseType::Float && !out {
                        if tvar.is_none() {
                            return None;
                        }
                        score += 2;
                    } else {
                        return None;
                    }
                }
                'x' => {}
                c => {
                    let want = builtins::code_type(c)?;
                    if v.ty == want {
                    } else if want.is_triple() && v.ty.is_triple() {
                        score += 1;
                        if (want == BaseType::Color) != (v.ty == BaseType::Color) {
                            score += 2;
                        }
                    } else if v.ty == BaseType::Float && (want.is_triple()) && !out {
                        score += 2;
                    } else {
                        return None;
                    }
                }
            }
        }
        // Return-type preference from the context.
        let ret = resolve_code(s.ret, tvar);
        match (hint, ret) {
            (Some(h), Some(r)) if h == r => {}
            (Some(h), Some(r)) if h.is_triple() && r.is_triple() => score += 1,
            (Some(BaseType::Float), Some(r)) if r.is_triple() => score += 4,
            (Some(h), Some(BaseType::Float)) if h.is_triple() => score += 3,
            // RISpec's trace() is a colour (the float form, its luminance, is an extension):
            // without a hint it stays a colour.
            (None, Some(r))
                if r.is_triple()
                    && matches!(s.ret, 'c' | 'p' | 'v')
                    && !matches!(s.f, Builtin::Trace) =>
            {
                score += 4
            }
            _ => {}
        }
        if (s.ret == 't' || s.ret == 'q') && tvar.is_none() {
            return None;
        }
        Some((score, tvar))
    }

    fn user_call(
        &mut self,
        name: &str,
        entries: Vec<FuncEntry>,
        args: &[Expr],
        span: Span,
        hint: Option<BaseType>,
    ) -> Val {
        if self.inline_stack.iter().any(|n| n == name) {
            return self.error(
                Diag::error(
                    "sl::recursion",
                    format!("`{name}` calls itself; the shading language has no recursion"),
                )
                .label(span, "recursive call"),
            );
        }
        // Lower arguments (output formals need lvalues; read them as values too).
        let vals: Vec<Val> = args.iter().map(|a| self.expr(a, None)).collect();
        // Choose by argument count and type compatibility, then return-type hint.
        let mut best: Option<(u32, FuncEntry)> = None;
        for e in &entries {
            let formals = flatten_formals(&e.def.params);
            if formals.len() != vals.len() {
                continue;
            }
            let mut score = 0;
            let mut ok = true;
            for (f, v) in formals.iter().zip(&vals) {
                let fa = f.array.map(|a| match a {
                    ArraySpec::Sized(n) => n,
                    ArraySpec::Unsized => v.array.unwrap_or(0),
                });
                if fa != v.array {
                    ok = false;
                    break;
                }
                if f.ty.base == v.ty {
                } else if f.ty.base.is_triple() && v.ty.is_triple() {
                    score += 1;
                } else if v.ty == BaseType::Float
                    && (f.ty.base.is_triple() || f.ty.base == BaseType::Matrix)
                    && !f.output
                {
                    score += 2;
                } else {
                    ok = false;
                    break;
                }
            }
            if !ok {
                continue;
            }
            if let Some(h) = hint {
                if h != e.def.ret.base {
                    score += 1;
                }
            }
            if best.as_ref().map_or(true, |b| score < b.0) {
                best = Some((score, e.clone()));
            }
        }
        let Some((_, entry)) = best else {
            let found: Vec<String> = vals.iter().map(|v| ty_name(v.ty, v.array)).collect();
            return self.error(
                Diag::error(
                    "sl::call",
                    format!("no definition of `{name}` takes ({})", found.join(", ")),
                )
                .label(span, "call")
                .label(entries[0].def.name_span, "defined here"),
            );
        };
        let def = entry.def.clone();
        // Bind formals in a fresh scope that sees only the definition's lexical scopes.
        let saved_scopes = self.scopes.split_off(entry.depth.min(self.scopes.len()));
        let saved_funcs = self.funcs.split_off(entry.depth.min(self.funcs.len()));
        self.push_scope();
        let formals = flatten_formals(&def.params);
        for ((f, v), a) in formals.iter().zip(&vals).zip(args) {
            if f.output {
                // Alias the caller's variable so writes reach it.
                let target = match &a.kind {
                    ExprKind::Ident(n) => {
                        // look the name up in the caller's scopes
                        saved_scopes
                            .iter()
                            .rev()
                            .find_map(|s| s.get(n))
                            .cloned()
                            .or_else(|| self.lookup(n))
                    }
                    _ => None,
                };
                match target {
                    Some(var) if var.writable => {
                        if var.ty != f.ty.base && !(var.ty.is_triple() && f.ty.base.is_triple()) {
                            self.diags.push(
                                Diag::error(
                                    "sl::type",
                                    format!(
                                        "output parameter `{}` is {} but the argument is {}",
                                        f.name,
                                        f.ty.base.name(),
                                        var.ty.name()
                                    ),
                                )
                                .label(a.span, "argument"),
                            );
                        }
                        let mut alias = var.clone();
                        alias.ty = f.ty.base;
                        self.declare(&f.name, alias);
                    }
                    _ => {
                        self.diags.push(
                            Diag::error(
                                "sl::call",
                                format!("output parameter `{}` needs a variable", f.name),
                            )
                            .label(a.span, "not a writable variable"),
                        );
                        let tmp = self.temp(f.ty.base, true);
                        self.declare(
                            &f.name,
                            Var {
                                ty: f.ty.base,
                                array: None,
                                varying: true,
                                reg: tmp.reg,
                                writable: true,
                                candidate: None,
                                decl_span: f.span,
                                decl_ctx: self.varying_ctx,
                            },
                        );
                    }
                }
            } else {
                let cv = if v.array.is_some() {
                    *v
                } else {
                    self.coerce(*v, f.ty.base, a.span)
                };
                // The body is inlined, so the parameter simply takes the argument's detail.
                if f.ty.detail == Some(Detail::Uniform) && cv.varying {
                    self.diags.push(
                        Diag::warning(
                            "sl::detail",
                            format!(
                                "parameter `{}` is uniform but the argument is varying; it is treated as varying",
                                f.name
                            ),
                        )
                        .label(a.span, "varying argument")
                        .label(f.span, "declared uniform here"),
                    );
                }
                self.declare(
                    &f.name,
                    Var {
                        ty: f.ty.base,
                        array: cv.array,
                        varying: cv.varying,
                        reg: cv.reg,
                        writable: false,
                        candidate: None,
                        decl_span: f.span,
                        decl_ctx: self.varying_ctx,
                    },
                );
            }
        }
        let ret = if def.ret.base == BaseType::Void {
            None
        } else {
            let demoted = self.forced.contains(&def.name_span);
            let varying = match def.ret.detail {
                Some(Detail::Varying) => true,
                // Declared `uniform` but returning a value made varying (a uniform global it
                // updates was demoted, as in Advanced RenderMan's lensflare `urand`): the
                // result is varying with a warning, like an explicitly uniform local.
                Some(Detail::Uniform) => {
                    if demoted {
                        self.diags.push(
                            Diag::warning(
                                "sl::detail",
                                format!(
                                    "function `{name}` is declared to return a uniform value \
                                     but returns a varying one; it is treated as varying"
                                ),
                            )
                            .label(def.name_span, "declared uniform here")
                            .help("declare the return type `varying` (or leave the detail out)"),
                        );
                    }
                    demoted
                }
                None => demoted,
            };
            let reg = self.new_reg(Kind::of(def.ret.base), varying);
            Some(Var {
                ty: def.ret.base,
                array: None,
                varying,
                reg,
                writable: true,
                candidate: if def.ret.detail != Some(Detail::Varying) {
                    Some(def.name_span)
                } else {
                    None
                },
                decl_span: def.name_span,
                decl_ctx: self.varying_ctx,
            })
        };
        let fctx = self.varying_ctx;
        let forced_fn = self.forced.contains(&def.span);
        if forced_fn {
            self.varying_ctx += 1;
        }
        self.fn_frames.push(FuncFrame {
            ret: ret.clone(),
            varying_ctx: fctx + u32::from(forced_fn),
            span: def.span,
        });
        self.inline_stack.push(name.to_string());
        // `break`/`continue` in the body count only the function's own loops: the caller's
        // loops are not reachable from inside a function.
        let caller_loops = std::mem::take(&mut self.loops);
        // Nested functions defined in the body are visible inside it.
        let (body, ()) = self.with_block(|lw| lw.block_stmts(&def.body));
        self.loops = caller_loops;
        self.inline_stack.pop();
        self.fn_frames.pop();
        if forced_fn {
            self.varying_ctx -= 1;
        }
        self.pop_scope();
        self.scopes.extend(saved_scopes);
        self.funcs.extend(saved_funcs);
        self.emit(Instr::Function { body });
        match ret {
            Some(r) => Val {
                reg: r.reg,
                ty: r.ty,
                varying: r.varying,
                array: None,
            },
            None => Val {
                reg: self.error_reg,
                ty: BaseType::Void,
                varying: false,
                array: None,
            },
        }
    }

    /// transform/vtransform/ntransform: ([from,] to, x), (m, x), (from, m, x).
    fn transform_call(&mut self, name: &str, args: &[Expr], span: Span) -> Val {
        let (kind, ty) = match name {
            "transform" => (XformKind::Point, BaseType::Point),
            "vtransform" => (XformKind::Vector, BaseType::Vector),
            _ => (XformKind::Normal, BaseType::Normal),
        };
        if args.len() < 2 || args.len() > 3 {
            return self.error(
                Diag::error(
                    "sl::call",
                    format!("`{name}` takes ([from,] to, x) or ([from,] matrix, x)"),
                )
                .label(span, "call"),
            );
        }
        let ops: Vec<Val> = args[..args.len() - 1]
            .iter()
            .map(|a| self.expr(a, None))
            .collect();
        let xe = &args[args.len() - 1];
        let x = self.expr(xe, Some(ty));
        let x = self.coerce(x, ty, xe.span);
        let mut spaces = Vec::new();
        for (v, a) in ops.iter().zip(args) {
            match v.ty {
                BaseType::String => spaces.push(Space::Named(v.reg)),
                BaseType::Matrix => spaces.push(Space::Matrix(v.reg)),
                _ => {
                    return self.error(
                        Diag::error(
                            "sl::call",
                            format!("`{name}` takes space names or a matrix before the value"),
                        )
                        .label(a.span, format!("this is {}", v.ty.name())),
                    )
                }
            }
        }
        let (from, to) = match spaces.as_slice() {
            [to] => (Space::Current, *to),
            [from, to] => {
                if matches!(from, Space::Matrix(_)) {
                    return self.error(
                        Diag::error(
                            "sl::call",
                            format!("`{name}`: the source space must be a name"),
                        )
                        .label(args[0].span, "matrix"),
                    );
                }
                (*from, *to)
            }
            _ => (Space::Current, Space::Current),
        };
        let varying = x.varying || ops.iter().any(|v| v.varying);
        let t = self.temp(x.ty, varying);
        self.emit(Instr::Transform {
            kind,
            dst: t.reg,
            from,
            to,
            a: x.reg,
            span,
        });
        t
    }

    /// spline with an array of knots: spline([basis,] x, array).
    fn spline_array(&mut self, args: &[Expr], span: Span, hint: Option<BaseType>) -> Option<Val> {
        let last = args.last()?;
        let (arr, _) = self.array_var(last)?;
        let mut regs = Vec::new();
        let mut i = 0;
        let mut basis = false;
        if args.len() == 3 {
            let b = self.expr(&args[0], Some(BaseType::String));
            let b = self.coerce(b, BaseType::String, args[0].span);
            regs.push(b.reg);
            basis = true;
            i = 1;
        } else if args.len() != 2 {
            return Some(
                self.error(
                    Diag::error("sl::call", "spline with an array takes ([basis,] x, array)")
                        .label(span, "call"),
                ),
            );
        }
        let x = self.expr(&args[i], Some(BaseType::Float));
        let x = self.coerce(x, BaseType::Float, args[i].span);
        regs.push(x.reg);
        let n = arr.array.unwrap_or(1);
        for k in 0..n {
            regs.push(arr.reg + k as Reg);
        }
        let _ = hint;
        let ty = arr.ty;
        let f = match (basis, ty == BaseType::Float) {
            (false, true) => Builtin::SplineArrayF,
            (false, false) => Builtin::SplineArrayT,
            (true, true) => Builtin::SplineBasisArrayF,
            (true, false) => Builtin::SplineBasisArrayT,
        };
        let t = self.temp(ty, x.varying || arr.varying);
        self.emit(Instr::Call {
            f,
            dst: t.reg,
            args: regs,
            span,
        });
        Some(t)
    }

    /// texture/environment/shadow/bump: (name[chan], coordinates…, "param", value, …).
    fn texture_call(
        &mut self,
        name: &str,
        args: &[Expr],
        span: Span,
        hint: Option<BaseType>,
    ) -> Val {
        let Some(first) = args.first() else {
            return self.error(
                Diag::error("sl::call", format!("`{name}` needs a map name")).label(span, "call"),
            );
        };
        // name[channel]
        let (map, chan) = match &first.kind {
            ExprKind::Index { base, index } => {
                let m = self.expr(base, Some(BaseType::String));
                let c = self.expr(index, Some(BaseType::Float));
                (m, self.coerce(c, BaseType::Float, index.span))
            }
            _ => (
                self.expr(first, Some(BaseType::String)),
                self.const_val(Const::F(0.0), BaseType::Float),
            ),
        };
        if map.ty != BaseType::String {
            return self.error(
                Diag::error(
                    "sl::call",
                    format!("`{name}` takes a map name (a string) first"),
                )
                .label(first.span, "not a string"),
            );
        }
        // Positional coordinates until the first string argument.
        let mut coords = Vec::new();
        let mut k = 1;
        while k < args.len() {
            let v = self.expr(&args[k], None);
            if v.ty == BaseType::String {
                break;
            }
            coords.push((v, args[k].span));
            k += 1;
        }
        let params = self.param_pairs(name, args, k);
        // bump(name, N, dPds, dPdt, [coordinates], …) (RISpec 3.0/3.1 §15.7; 3.2 dropped
        // it): the frame comes first, then the coordinates as for texture().
        let mut frame = Vec::new();
        if name == "bump" {
            if coords.len() < 3 {
                return self.error(
                    Diag::error(
                        "sl::call",
                        "`bump` takes the normal N and the vectors dPds, dPdt after the map name",
                    )
                    .label(span, "call")
                    .help("N += bump(\"map.tex\", N, dPdu, dPdv);"),
                );
            }
            for (i, (v, sp)) in coords.drain(..3).enumerate() {
                let ty = if i == 0 {
                    BaseType::Normal
                } else {
                    BaseType::Vector
                };
                frame.push(self.coerce(v, ty, sp).reg);
            }
        }
        let (coord_ty, counts): (BaseType, &[usize]) = match name {
            "texture" => (BaseType::Float, &[0, 2, 8]),
            "environment" => (BaseType::Vector, &[1, 4]),
            "bump" => (BaseType::Float, &[0, 2, 8]),
            _ => (BaseType::Point, &[1, 4]),
        };
        if !counts.contains(&coords.len()) {
            return self.error(
                Diag::error(
                    "sl::call",
                    format!(
                        "`{name}` takes {:?} coordinates, found {}",
                        counts,
                        coords.len()
                    ),
                )
                .label(span, "call"),
            );
        }
        let mut regs = vec![map.reg, chan.reg, self.const_float(coords.len() as f32)];
        regs.extend(frame);
        if coords.is_empty() {
            // default coordinates (s, t)
            for g in ["s", "t"] {
                match self.lookup(g) {
                    Some(v) => {
                        self.mark_used(v.reg);
                        regs.push(v.reg);
                    }
                    None => {
                        return self.error(
                            Diag::error(
                                "sl::call",
                                format!("`{name}` without coordinates needs s and t"),
                            )
                            .label(span, "call"),
                        )
                    }
                }
            }
        }
        for (v, sp) in coords {
            let c = self.coerce(v, coord_ty, sp);
            regs.push(c.reg);
        }
        regs.extend(params);
        let (f, ty) = match name {
            "texture" => {
                if matches!(hint, Some(h) if h.is_triple()) {
                    (Builtin::TextureC, BaseType::Color)
                } else {
                    (Builtin::TextureF, BaseType::Float)
                }
            }
            "environment" => {
                if matches!(hint, Some(h) if h.is_triple()) {
                    (Builtin::EnvironmentC, BaseType::Color)
                } else {
                    (Builtin::EnvironmentF, BaseType::Float)
                }
            }
            "bump" => (Builtin::Bump, BaseType::Point),
            _ => (Builtin::Shadow, BaseType::Float),
        };
        // Always varying: the filter footprint comes from the coordinates' derivatives, which
        // differ per point even when the coordinates are uniform expressions of s and t.
        let t = self.temp(ty, true);
        self.emit(Instr::Call {
            f,
            dst: t.reg,
            args: regs,
            span,
        });
        t
    }

    /// Ray functions with positional arguments then "name", value pairs:
    /// `occlusion(P, N, samples, …)`, `indirectdiffuse(P, N, samples, …)`,
    /// `transmission(Psrc, Pdst, …)`, `visibility(P1, P2)`.
    fn ray_call(&mut self, name: &str, args: &[Expr], span: Span) -> Val {
        let (f, ret, pos): (Builtin, BaseType, &[BaseType]) = match name {
            "occlusion" => (
                Builtin::Occlusion,
                BaseType::Float,
                &[BaseType::Point, BaseType::Normal, BaseType::Float],
            ),
            "indirectdiffuse" => (
                Builtin::IndirectDiffuse,
                BaseType::Color,
                &[BaseType::Point, BaseType::Normal, BaseType::Float],
            ),
            "transmission" => (
                Builtin::Transmission,
                BaseType::Color,
                &[BaseType::Point, BaseType::Point],
            ),
            _ => (
                Builtin::Visibility,
                BaseType::Color,
                &[BaseType::Point, BaseType::Point],
            ),
        };
        // Aqsis's `occlusion(mapname, P, N, samples, …)` reads a set of shadow maps rendered
        // around the scene; arbor traces the same hemisphere against the scene instead.
        let map_form = matches!(name, "occlusion" | "indirectdiffuse")
            && args.len() >= 4
            && self.is_string_expr(&args[0]);
        let args = if map_form {
            self.warn_extension(
                "occlusion map",
                args[0].span,
                &format!(
                    "`{name}` from a map (Aqsis's `{name}(mapname, P, N, samples)`): arbor traces \
                     rays against the scene and does not read the map"
                ),
            );
            &args[1..]
        } else {
            args
        };
        let mut regs = Vec::new();
        let mut k = 0;
        while k < args.len() && k < pos.len() {
            let v = self.expr(&args[k], Some(pos[k]));
            if v.ty == BaseType::String {
                break;
            }
            let v = self.coerce(v, pos[k], args[k].span);
            regs.push(v.reg);
            k += 1;
        }
        // PRMan's occlusion/indirectdiffuse without a sample count: 16 (arbor's default).
        if regs.len() == 2 && pos.len() == 3 {
            regs.push(self.const_float(16.0));
        }
        // The map form's count is the map lookup's (Aqsis's examples pass 0 and give
        // "samples" as a parameter): a constant below 1 means arbor's default.
        if map_form && regs.len() == 3 {
            let low = matches!(self.const_values.get(&regs[2]), Some(Const::F(x)) if *x < 1.0);
            if low {
                regs[2] = self.const_float(16.0);
            }
        }
        if regs.len() != pos.len() {
            return self.error(
                Diag::error(
                    "sl::call",
                    format!(
                        "`{name}` takes {} positional arguments, found {}",
                        pos.len(),
                        k
                    ),
                )
                .label(span, "call")
                .help(match name {
                    "occlusion" => "occlusion(P, N, samples, \"maxdist\", d)",
                    "indirectdiffuse" => "indirectdiffuse(P, N, samples)",
                    _ => "transmission(Ps, lightposition)",
                }),
            );
        }
        regs.extend(self.param_pairs(name, args, k));
        let t = self.temp(ret, true);
        self.emit(Instr::Call {
            f,
            dst: t.reg,
            args: regs,
            span,
        });
        t
    }

    /// Optional `"name", value` pairs of a ray call that arbor does not use (one ray per
    /// point, arbor's own bias): each value is evaluated and each name but those in `silent`
    /// (names that only label rays) gets one warning.
    fn unused_ray_params(&mut self, call: &str, args: &[Expr], from: usize, silent: &[&str]) {
        let mut k = from;
        while k < args.len() {
            let pn = self.expr(&args[k], Some(BaseType::String));
            if let Some(v) = args.get(k + 1) {
                self.expr(v, None);
            }
            let name = match &args[k].kind {
                ExprKind::Str(n) => n.clone(),
                _ => String::from("(computed name)"),
            };
            if pn.ty != BaseType::String {
                self.diags.push(
                    Diag::error(
                        "sl::call",
                        format!("`{call}` parameters come in \"name\", value pairs"),
                    )
                    .label(args[k].span, "expected a parameter name"),
                );
            } else if !silent.contains(&name.as_str()) {
                self.diags.push(
                    Diag::warning(
                        "sl::unsupported",
                        format!("`{call}` parameter \"{name}\" is not used by arbor"),
                    )
                    .label(args[k].span, "not used")
                    .help("arbor traces one ray per shading point with its own bias"),
                );
            }
            k += 2;
        }
    }

    /// Whether `e` is a string without lowering it: a literal, or a variable or parameter
    /// declared `string`.
    fn is_string_expr(&self, e: &Expr) -> bool {
        match &e.kind {
            ExprKind::Str(_) => true,
            ExprKind::Ident(n) => self.lookup(n).is_some_and(|v| v.ty == BaseType::String),
            _ => false,
        }
    }

    /// The `"name", value` pairs of a call from argument `k` on: their registers in order.
    /// A pair that is not one is reported and ends the list.
    fn param_pairs(&mut self, name: &str, args: &[Expr], mut k: usize) -> Vec<Reg> {
        let mut regs = Vec::new();
        while k < args.len() {
            let pn = self.expr(&args[k], Some(BaseType::String));
            if pn.ty != BaseType::String {
                self.diags.push(
                    Diag::error(
                        "sl::call",
                        format!("`{name}` parameters come in \"name\", value pairs"),
                    )
                    .label(args[k].span, "expected a parameter name"),
                );
                break;
            }
            // PRMan's area shadows: `"source"` is followed by the four corners of the light
            // (`shadow(maps, Ps, "source", P1, P2, P3, P4, …)`); each becomes a pair.
            let source =
                name == "shadow" && matches!(&args[k].kind, ExprKind::Str(s) if s == "source");
            if source {
                let mut corners = 0;
                while corners < 4
                    && args
                        .get(k + 1 + corners)
                        .is_some_and(|a| !self.is_string_expr(a))
                {
                    let pv = self.expr(&args[k + 1 + corners], Some(BaseType::Point));
                    regs.push(pn.reg);
                    regs.push(pv.reg);
                    corners += 1;
                }
                if corners > 0 {
                    k += 1 + corners;
                    continue;
                }
            }
            let Some(val) = args.get(k + 1) else {
                self.diags.push(
                    Diag::error("sl::call", format!("`{name}` parameter without a value"))
                        .label(args[k].span, "no value"),
                );
                break;
            };
            let pv = self.expr(val, None);
            regs.push(pn.reg);
            regs.push(pv.reg);
            k += 2;
        }
        regs
    }

    fn filterstep(&mut self, args: &[Expr], span: Span) -> Val {
        let mut regs = Vec::new();
        let mut k = 0;
        let mut varying = true;
        while k < args.len() && k < 3 {
            let v = self.expr(&args[k], Some(BaseType::Float));
            if v.ty == BaseType::String {
                break;
            }
            let v = self.coerce(v, BaseType::Float, args[k].span);
            varying |= v.varying;
            regs.push(v.reg);
            k += 1;
        }
        if regs.len() < 2 {
            return self.error(
                Diag::error(
                    "sl::call",
                    "`filterstep` takes (edge, s1 [, s2] [, \"param\", value…])",
                )
                .label(span, "call"),
            );
        }
        let npos = regs.len();
        let mut params = Vec::new();
        while k + 1 < args.len() {
            let pn = self.expr(&args[k], Some(BaseType::String));
            let pv = self.expr(&args[k + 1], None);
            params.push(pn.reg);
            params.push(pv.reg);
            k += 2;
        }
        let mut all = vec![self.const_float(npos as f32)];
        all.extend(regs);
        all.extend(params);
        let t = self.temp(BaseType::Float, varying);
        self.emit(Instr::Call {
            f: Builtin::FilterStep,
            dst: t.reg,
            args: all,
            span,
        });
        t
    }

    fn printf(&mut self, name: &str, args: &[Expr], span: Span) -> Val {
        let mut regs = Vec::new();
        let mut varying = false;
        for (i, a) in args.iter().enumerate() {
            let v = self.expr(a, None);
            if i == 0 && v.ty != BaseType::String {
                self.diags.push(
                    Diag::error("sl::call", format!("`{name}` takes a format string first"))
                        .label(a.span, "not a string"),
                );
            }
            varying |= v.varying;
            regs.push(v.reg);
        }
        if name == "printf" {
            let t = self.temp(BaseType::Void, false);
            self.emit(Instr::Call {
                f: Builtin::Printf,
                dst: t.reg,
                args: regs,
                span,
            });
            Val {
                ty: BaseType::Void,
                ..t
            }
        } else {
            let t = self.temp(BaseType::String, false);
            let _ = varying;
            self.emit(Instr::Call {
                f: Builtin::Format,
                dst: t.reg,
                args: regs,
                span,
            });
            t
        }
    }

    /// Message passing and information: f(name, output var) → 1 on success.
    fn message(&mut self, name: &str, args: &[Expr], span: Span) -> Val {
        let (nin, f) = match name {
            "textureinfo" => (2, Builtin::TextureInfo),
            _ => (1, Builtin::Message),
        };
        if args.len() != nin + 1 {
            return self.error(
                Diag::error(
                    "sl::call",
                    format!("`{name}` takes {} names and an output variable", nin),
                )
                .label(span, "call"),
            );
        }
        let which = self.const_val(Const::S(Arc::from(name)), BaseType::String);
        let mut regs = vec![which.reg];
        for a in &args[..nin] {
            let v = self.expr(a, Some(BaseType::String));
            let v = self.coerce(v, BaseType::String, a.span);
            regs.push(v.reg);
        }
        let target = &args[nin];
        // The output variable (or array): temporaries holding the current values.
        let (var, base_reg) = match &target.kind {
            ExprKind::Ident(n) => match self.lookup(n) {
                Some(v) if v.writable => (v.clone(), v.reg),
                _ => {
                    return self.error(
                        Diag::error(
                            "sl::call",
                            format!("`{name}` needs a writable variable to store into"),
                        )
                        .label(target.span, "not writable"),
                    )
                }
            },
            _ => {
                return self.error(
                    Diag::error("sl::call", format!("`{name}` stores into a variable"))
                        .label(target.span, "not a variable"),
                )
            }
        };
        let n = var.array.unwrap_or(1);
        // Values passed from another shader vary over the grid: the variable receiving one
        // becomes varying (a `float h = 0` read by `displacement("hump", h)` would otherwise
        // keep one value per grid).
        let varying = matches!(
            name,
            "lightsource" | "displacement" | "surface" | "atmosphere" | "incident" | "opposite"
        ) || var.varying;
        let tys = self.const_val(Const::S(Arc::from(var.ty.name())), BaseType::String);
        regs.push(tys.reg);
        let mut temps = Vec::new();
        for k in 0..n {
            let t = self.temp(var.ty, varying);
            self.emit(Instr::Copy {
                dst: t.reg,
                src: base_reg + k as Reg,
            });
            regs.push(t.reg);
            temps.push(t);
        }
        let ok = self.temp(BaseType::Float, varying);
        self.emit(Instr::Call {
            f,
            dst: ok.reg,
            args: regs,
            span,
        });
        for (k, t) in temps.into_iter().enumerate() {
            self.store_reg(&var, var.reg + k as Reg, t, target.span);
        }
        self.mark_written(var.reg);
        ok
    }
}

fn var_val(v: &Var) -> Val {
    Val {
        reg: v.reg,
        ty: v.ty,
        varying: v.varying,
        array: v.array,
    }
}

/// Function formals as written `(float a, b; output color c)` are already one per name in the
/// AST; this keeps one place to change if that ever differs.
fn flatten_formals(f: &[Formal]) -> Vec<&Formal> {
    f.iter().collect()
}

/// The arithmetic of a compound assignment (`+=` is `+`); None for plain `=`.
fn compound_op(op: AssignOp) -> Option<BinOp> {
    match op {
        AssignOp::Set => None,
        AssignOp::Add => Some(BinOp::Add),
        AssignOp::Sub => Some(BinOp::Sub),
        AssignOp::Mul => Some(BinOp::Mul),
        AssignOp::Div => Some(BinOp::Div),
    }
}

fn resolve_code(c: char, tvar: Option<BaseType>) -> Option<BaseType> {
    match c {
        't' | 'q' => tvar,
        c => builtins::code_type(c),
    }
}

fn always_varying(f: Builtin) -> bool {
    use Builtin::*;
    matches!(
        f,
        DuF | DvF
            | DuT
            | DvT
            | DerivF
            | DerivT
            | Area
            | CalculateNormal
            | RandomF
            | RandomT
            | Ambient
            | Diffuse
            | Specular
            | SpecularBrdf
            | Phong
            | Trace
            | Depth
            | Horizon
            | HorizonHeight
    )
}

fn sig_text(s: &Sig) -> String {
    let (codes, rep) = builtins::parse_args(s.args);
    let mut parts: Vec<String> = codes
        .iter()
        .map(|(c, out)| {
            let n = match c {
                't' => "triple",
                'q' => "point/vector/normal",
                'x' => "any",
                c => builtins::code_type(*c).map(|t| t.name()).unwrap_or("?"),
            };
            if *out {
                format!("output {n}")
            } else {
                n.to_string()
            }
        })
        .collect();
    if rep {
        parts.push("…".into());
    }
    format!("({})", parts.join(", "))
}
