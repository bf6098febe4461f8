//! The compiled form of a shader: a tree of instructions over virtual registers.
//!
//! Input: produced by `lower` from a checked AST. Output: executed by `shade::exec` over a whole
//! grid at once. Invariants: every register has one storage kind and one detail for the whole
//! program; uniform registers hold one value, varying registers one value per grid point;
//! computation instructions write only temporaries (never a source operand) and run over every
//! point; only `Mov`/`SetIndex` (stores to variables) honour the running mask. Control flow is
//! structured (if/loop/function frames) so the mask can be narrowed and restored.

use std::fmt;
use std::sync::Arc;

use glam::{Mat4, Vec3};

use crate::diag::Span;
use crate::sl::ast::{BaseType, ShaderKind};
use crate::sl::builtins::Builtin;

pub type Reg = u32;

/// Storage kind of a register.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kind {
    Float,
    Triple,
    Matrix,
    Str,
}

impl Kind {
    pub fn of(base: BaseType) -> Kind {
        match base {
            BaseType::Float | BaseType::Void => Kind::Float,
            BaseType::String => Kind::Str,
            BaseType::Matrix => Kind::Matrix,
            _ => Kind::Triple,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RegInfo {
    pub kind: Kind,
    pub varying: bool,
}

/// A constant value.
#[derive(Clone, Debug, PartialEq)]
pub enum Const {
    F(f32),
    T(Vec3),
    M(Mat4),
    S(Arc<str>),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cmp {
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
}

/// Arithmetic on one storage kind (both operands already converted to it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Arith {
    Add,
    Sub,
    Mul,
    Div,
}

/// How a point-like value transforms.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum XformKind {
    Point,
    Vector,
    Normal,
}

/// A coordinate system operand: a named space (string register) or a matrix register.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Space {
    Current,
    Named(Reg),
    Matrix(Reg),
}

#[derive(Clone, Debug, PartialEq)]
pub enum Instr {
    /// dst = src under the running mask (broadcasting a uniform source).
    Mov {
        dst: Reg,
        src: Reg,
    },
    /// Unmasked copy into a temporary.
    Copy {
        dst: Reg,
        src: Reg,
    },
    Arith {
        op: Arith,
        kind: Kind,
        dst: Reg,
        a: Reg,
        b: Reg,
        /// The operator's expression, where a division by zero is reported.
        span: Span,
    },
    /// triple · float / float · triple scaling is lowered as Promote + Arith.
    Neg {
        kind: Kind,
        dst: Reg,
        a: Reg,
    },
    /// float → triple (x,x,x) or float → matrix (x·I).
    Promote {
        to: Kind,
        dst: Reg,
        a: Reg,
    },
    Dot {
        dst: Reg,
        a: Reg,
        b: Reg,
    },
    Cross {
        dst: Reg,
        a: Reg,
        b: Reg,
    },
    Compare {
        op: Cmp,
        kind: Kind,
        dst: Reg,
        a: Reg,
        b: Reg,
    },
    And {
        dst: Reg,
        a: Reg,
        b: Reg,
    },
    Or {
        dst: Reg,
        a: Reg,
        b: Reg,
    },
    Not {
        dst: Reg,
        a: Reg,
    },
    /// dst = cond ? a : b (both evaluated).
    Select {
        kind: Kind,
        dst: Reg,
        cond: Reg,
        a: Reg,
        b: Reg,
    },
    /// (x, y, z) → triple
    MakeTriple {
        dst: Reg,
        x: Reg,
        y: Reg,
        z: Reg,
    },
    /// 16 floats → matrix (row-major as written).
    MakeMatrix {
        dst: Reg,
        elems: Box<[Reg; 16]>,
    },
    /// Converts a triple from a colour space to rgb.
    ColorFrom {
        dst: Reg,
        space: Reg,
        a: Reg,
    },
    /// Transforms from `from` to `to` space.
    Transform {
        kind: XformKind,
        dst: Reg,
        from: Space,
        to: Space,
        a: Reg,
    },
    /// matrix "space" x: the matrix that maps `space` to current, times x.
    SpaceMatrix {
        dst: Reg,
        space: Reg,
    },
    /// Array element read with a (possibly varying) index; `base..base+len` hold the elements.
    GetIndex {
        kind: Kind,
        dst: Reg,
        base: Reg,
        len: u32,
        index: Reg,
        span: Span,
    },
    /// Array element store under the mask.
    SetIndex {
        kind: Kind,
        base: Reg,
        len: u32,
        index: Reg,
        src: Reg,
        span: Span,
    },
    /// A built-in function.
    Call {
        f: Builtin,
        dst: Reg,
        args: Vec<Reg>,
        span: Span,
    },
    If {
        cond: Reg,
        then: Vec<Instr>,
        otherwise: Vec<Instr>,
    },
    /// `cond_code` computes `cond`; body; step. `span` is the loop statement (named by the
    /// runaway-loop guard). `compact`: the registers the loop names and how it uses them,
    /// when it may run on its running points gathered into a smaller grid (see
    /// [`Program::mark_compact_loops`]).
    Loop {
        cond_code: Vec<Instr>,
        cond: Reg,
        body: Vec<Instr>,
        step: Vec<Instr>,
        span: Span,
        compact: Option<Vec<(Reg, CompactUse)>>,
    },
    Break(u32),
    Continue(u32),
    /// An inlined function body: `return` leaves it.
    Function {
        body: Vec<Instr>,
    },
    Return,
    /// illuminance: for every non-ambient light, with L (surface→light), Cl, Ol bound.
    Illuminance {
        category: Option<Reg>,
        pos: Reg,
        axis: Option<(Reg, Reg)>,
        body: Vec<Instr>,
    },
    /// illuminate(from [, axis, angle]) in light shaders.
    Illuminate {
        pos: Reg,
        axis: Option<(Reg, Reg)>,
        body: Vec<Instr>,
    },
    /// solar([axis, angle]) in light shaders.
    Solar {
        axis: Option<(Reg, Reg)>,
        body: Vec<Instr>,
    },
    /// gather(category, P, dir, angle, samples, "name", var…): per sample, rays from `pos`
    /// in a cone of half-angle `angle` around `dir`; `body` runs where the ray hit (with the
    /// `outputs` temporaries set: "surface:Ci", "surface:Oi", "ray:length", "ray:direction",
    /// "ray:origin", "primitive:P"), `otherwise` where it missed.
    Gather {
        pos: Reg,
        dir: Reg,
        angle: Reg,
        samples: Reg,
        outputs: Vec<(String, Reg)>,
        body: Vec<Instr>,
        otherwise: Vec<Instr>,
    },
}

/// A shader parameter as the program exposes it.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamInfo {
    pub name: String,
    pub ty: BaseType,
    pub array: Option<usize>,
    pub varying: bool,
    pub output: bool,
    /// First register of the value (arrays occupy `array` consecutive registers).
    pub reg: Reg,
    /// The default as a printable value, when it is constant.
    pub default_text: String,
}

/// The standard globals a program reads or writes, by name, with their registers.
#[derive(Clone, Debug, PartialEq)]
pub struct GlobalInfo {
    pub name: &'static str,
    pub reg: Reg,
    pub written: bool,
}

/// A compiled shader.
#[derive(Clone, Debug)]
pub struct Program {
    pub name: String,
    pub kind: ShaderKind,
    pub regs: Vec<RegInfo>,
    /// Registers holding constants, set before every run.
    pub consts: Vec<(Reg, Const)>,
    pub params: Vec<ParamInfo>,
    pub globals: Vec<GlobalInfo>,
    /// Computes parameter defaults (run before instance values are bound).
    pub init: Vec<Instr>,
    pub body: Vec<Instr>,
    /// Per register: a temporary whose one `Mov` may take its value (see [`Program::movable_temps`]).
    pub movable: Vec<bool>,
    /// Per register: computed at every point even when few run (see
    /// [`Program::full_width_regs`]); registers past the end count as true.
    pub full_width: Vec<bool>,
    /// The light category (`__category` parameter default), for light shaders.
    pub span: Span,
}

impl Program {
    pub fn global(&self, name: &str) -> Option<&GlobalInfo> {
        self.globals.iter().find(|g| g.name == name)
    }
    pub fn param(&self, name: &str) -> Option<&ParamInfo> {
        self.params.iter().find(|p| p.name == name)
    }
    /// Instruction count (recursively), for statistics and tests.
    pub fn instr_count(&self) -> usize {
        fn count(v: &[Instr]) -> usize {
            v.iter()
                .map(|i| {
                    1 + match i {
                        Instr::If {
                            then, otherwise, ..
                        } => count(then) + count(otherwise),
                        Instr::Loop {
                            cond_code,
                            body,
                            step,
                            ..
                        } => count(cond_code) + count(body) + count(step),
                        Instr::Function { body }
                        | Instr::Illuminance { body, .. }
                        | Instr::Illuminate { body, .. }
                        | Instr::Solar { body, .. } => count(body),
                        Instr::Gather {
                            body, otherwise, ..
                        } => count(body) + count(otherwise),
                        _ => 0,
                    }
                })
                .sum()
        }
        count(&self.init) + count(&self.body)
    }
}

fn r(reg: Reg) -> String {
    format!("r{reg}")
}

fn list(f: &mut fmt::Formatter<'_>, instrs: &[Instr], depth: usize) -> fmt::Result {
    for i in instrs {
        let pad = "  ".repeat(depth);
        match i {
            Instr::If {
                cond,
                then,
                otherwise,
            } => {
                writeln!(f, "{pad}if {}", r(*cond))?;
                list(f, then, depth + 1)?;
                if !otherwise.is_empty() {
                    writeln!(f, "{pad}else")?;
                    list(f, otherwise, depth + 1)?;
                }
            }
            Instr::Loop {
                cond_code,
                cond,
                body,
                step,
                ..
            } => {
                writeln!(f, "{pad}loop")?;
                list(f, cond_code, depth + 1)?;
                writeln!(f, "{pad}  while {}", r(*cond))?;
                list(f, body, depth + 1)?;
                if !step.is_empty() {
                    writeln!(f, "{pad}  step")?;
                    list(f, step, depth + 2)?;
                }
            }
            Instr::Function { body } => {
                writeln!(f, "{pad}function")?;
                list(f, body, depth + 1)?;
            }
            Instr::Illuminance {
                category,
                pos,
                axis,
                body,
            } => {
                writeln!(
                    f,
                    "{pad}illuminance cat={:?} P={} axis={:?}",
                    category,
                    r(*pos),
                    axis
                )?;
                list(f, body, depth + 1)?;
            }
            Instr::Illuminate { pos, axis, body } => {
                writeln!(f, "{pad}illuminate P={} axis={:?}", r(*pos), axis)?;
                list(f, body, depth + 1)?;
            }
            Instr::Solar { axis, body } => {
                writeln!(f, "{pad}solar axis={:?}", axis)?;
                list(f, body, depth + 1)?;
            }
            Instr::Gather {
                pos,
                dir,
                angle,
                samples,
                outputs,
                body,
                otherwise,
            } => {
                let outs: Vec<String> = outputs
                    .iter()
                    .map(|(n, reg)| format!("{n}→{}", r(*reg)))
                    .collect();
                writeln!(
                    f,
                    "{pad}gather P={} dir={} angle={} samples={} [{}]",
                    r(*pos),
                    r(*dir),
                    r(*angle),
                    r(*samples),
                    outs.join(", ")
                )?;
                list(f, body, depth + 1)?;
                writeln!(f, "{pad}else")?;
                list(f, otherwise, depth + 1)?;
            }
            Instr::Call {
                f: func, dst, args, ..
            } => {
                let a: Vec<String> = args.iter().map(|&x| r(x)).collect();
                writeln!(f, "{pad}{} = {:?}({})", r(*dst), func, a.join(", "))?;
            }
            Instr::Mov { dst, src } => writeln!(f, "{pad}{} <- {}", r(*dst), r(*src))?,
            Instr::Copy { dst, src } => writeln!(f, "{pad}{} = {}", r(*dst), r(*src))?,
            Instr::Arith {
                op,
                kind,
                dst,
                a,
                b,
                ..
            } => writeln!(
                f,
                "{pad}{} = {:?}.{:?} {} {}",
                r(*dst),
                op,
                kind,
                r(*a),
                r(*b)
            )?,
            other => writeln!(f, "{pad}{:?}", other)?,
        }
    }
    Ok(())
}

impl fmt::Display for Program {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{} {} ({} registers)",
            self.kind.name(),
            self.name,
            self.regs.len()
        )?;
        for p in &self.params {
            writeln!(
                f,
                "  param {}{}{} {} = {} -> {}",
                if p.output { "output " } else { "" },
                if p.varying { "varying " } else { "uniform " },
                p.ty.name(),
                p.name,
                p.default_text,
                r(p.reg)
            )?;
        }
        for (reg, c) in &self.consts {
            writeln!(f, "  const {} = {:?}", r(*reg), c)?;
        }
        for g in &self.globals {
            let detail = if self.regs[g.reg as usize].varying {
                "varying"
            } else {
                "uniform"
            };
            let w = if g.written { " (written)" } else { "" };
            writeln!(f, "  global {detail} {} -> {}{w}", g.name, r(g.reg))?;
        }
        writeln!(f, "init:")?;
        list(f, &self.init, 1)?;
        writeln!(f, "body:")?;
        list(f, &self.body, 1)
    }
}

/// Every register an instruction names (operands and destinations, not nested blocks);
/// array instructions name their whole element range. Used for register-use analysis.
fn instr_regs(ins: &Instr, out: &mut Vec<Reg>) {
    let space = |s: &Space, out: &mut Vec<Reg>| match s {
        Space::Current => {}
        Space::Named(r) | Space::Matrix(r) => out.push(*r),
    };
    match ins {
        Instr::Mov { dst, src } | Instr::Copy { dst, src } => out.extend([*dst, *src]),
        Instr::Arith { dst, a, b, .. }
        | Instr::Dot { dst, a, b }
        | Instr::Cross { dst, a, b }
        | Instr::Compare { dst, a, b, .. }
        | Instr::And { dst, a, b }
        | Instr::Or { dst, a, b } => out.extend([*dst, *a, *b]),
        Instr::Neg { dst, a, .. } | Instr::Promote { dst, a, .. } | Instr::Not { dst, a } => {
            out.extend([*dst, *a])
        }
        Instr::Select {
            dst, cond, a, b, ..
        } => out.extend([*dst, *cond, *a, *b]),
        Instr::MakeTriple { dst, x, y, z } => out.extend([*dst, *x, *y, *z]),
        Instr::MakeMatrix { dst, elems } => {
            out.push(*dst);
            out.extend(elems.iter());
        }
        Instr::ColorFrom { dst, space, a } => out.extend([*dst, *space, *a]),
        Instr::Transform {
            dst, from, to, a, ..
        } => {
            out.extend([*dst, *a]);
            space(from, out);
            space(to, out);
        }
        Instr::SpaceMatrix { dst, space } => out.extend([*dst, *space]),
        Instr::GetIndex {
            dst,
            base,
            len,
            index,
            ..
        } => {
            out.extend([*dst, *index]);
            out.extend(*base..*base + *len);
        }
        Instr::SetIndex {
            base,
            len,
            index,
            src,
            ..
        } => {
            out.extend([*index, *src]);
            out.extend(*base..*base + *len);
        }
        Instr::Call { dst, args, .. } => {
            out.push(*dst);
            out.extend(args.iter());
        }
        Instr::If { cond, .. } | Instr::Loop { cond, .. } => out.push(*cond),
        Instr::Illuminance {
            category,
            pos,
            axis,
            ..
        } => {
            out.extend(category.iter());
            out.push(*pos);
            if let Some((a, b)) = axis {
                out.extend([*a, *b]);
            }
        }
        Instr::Illuminate { pos, axis, .. } => {
            out.push(*pos);
            if let Some((a, b)) = axis {
                out.extend([*a, *b]);
            }
        }
        Instr::Solar { axis, .. } => {
            if let Some((a, b)) = axis {
                out.extend([*a, *b]);
            }
        }
        Instr::Gather {
            pos,
            dir,
            angle,
            samples,
            outputs,
            ..
        } => {
            out.extend([*pos, *dir, *angle, *samples]);
            out.extend(outputs.iter().map(|(_, r)| *r));
        }
        Instr::Break(_) | Instr::Continue(_) | Instr::Function { .. } | Instr::Return => {}
    }
}

/// How a compacted loop uses a register it names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CompactUse {
    /// Only read: gathered at the loop's points; the whole-grid value is put back after.
    Read,
    /// Stored to (a variable): gathered, and scattered back after the loop.
    Stored,
    /// A temporary a pointwise instruction in the loop computes: every read of it in the
    /// loop follows its computation in the same iteration, and nothing after the loop reads
    /// it (it is not full-width), so it is neither gathered nor scattered.
    Temp,
}

/// The registers loop `ins` names (sorted, once each) and how, when it may run compacted
/// (see [`Program::mark_compact_loops`]).
fn compact_loop_regs(ins: &Instr, full: &[bool]) -> Option<Vec<(Reg, CompactUse)>> {
    let Instr::Loop {
        cond_code,
        cond,
        body,
        step,
        ..
    } = ins
    else {
        return None;
    };
    /// `depth`: frames between this code and the compacted loop's own (1 in its blocks);
    /// `in_fn`: inside an inlined function body that starts within the loop.
    fn ok(code: &[Instr], depth: u32, in_fn: bool, full: &[bool], regs: &mut Vec<Reg>) -> bool {
        for ins in code {
            let fine = match ins {
                Instr::Mov { .. } | Instr::If { .. } => true,
                Instr::Loop {
                    cond_code,
                    body,
                    step,
                    ..
                } => [cond_code, body, step]
                    .iter()
                    .all(|b| ok(b, depth + 1, in_fn, full, regs)),
                Instr::Function { body } => ok(body, depth + 1, true, full, regs),
                Instr::Break(k) | Instr::Continue(k) => *k <= depth,
                Instr::Return => in_fn,
                other => match other.pointwise_dst() {
                    Some(d) => !full.get(d as usize).copied().unwrap_or(true),
                    None => false,
                },
            };
            if !fine {
                return false;
            }
            if let Instr::If {
                then, otherwise, ..
            } = ins
            {
                if !ok(then, depth, in_fn, full, regs) || !ok(otherwise, depth, in_fn, full, regs) {
                    return false;
                }
            }
            instr_regs(ins, regs);
        }
        true
    }
    let mut regs = vec![*cond];
    if ![cond_code, body, step]
        .iter()
        .all(|b| ok(b, 1, false, full, &mut regs))
    {
        return None;
    }
    regs.sort_unstable();
    regs.dedup();
    // Which of them the loop stores to, and which it computes as temporaries.
    fn writes(code: &[Instr], stored: &mut Vec<Reg>, temps: &mut Vec<Reg>) {
        for ins in code {
            match ins {
                Instr::Mov { dst, .. } => stored.push(*dst),
                other => {
                    if let Some(d) = other.pointwise_dst() {
                        temps.push(d);
                    }
                }
            }
            for b in nested(ins) {
                writes(b, stored, temps);
            }
        }
    }
    let (mut stored, mut temps) = (Vec::new(), Vec::new());
    for b in [cond_code, body, step] {
        writes(b, &mut stored, &mut temps);
    }
    Some(
        regs.into_iter()
            .map(|r| {
                let u = if stored.contains(&r) {
                    CompactUse::Stored
                } else if temps.contains(&r) {
                    CompactUse::Temp
                } else {
                    CompactUse::Read
                };
                (r, u)
            })
            .collect(),
    )
}

fn nested(ins: &Instr) -> Vec<&[Instr]> {
    match ins {
        Instr::If {
            then, otherwise, ..
        } => vec![then, otherwise],
        Instr::Loop {
            cond_code,
            body,
            step,
            ..
        } => vec![cond_code, body, step],
        Instr::Function { body }
        | Instr::Illuminance { body, .. }
        | Instr::Illuminate { body, .. }
        | Instr::Solar { body, .. } => vec![body],
        Instr::Gather {
            body, otherwise, ..
        } => vec![body, otherwise],
        _ => vec![],
    }
}

impl Instr {
    /// A computation whose result at a point depends only on its operands at that point and
    /// that writes only its destination: under a sparse running mask it may compute just the
    /// running points (the others keep older values), unless its destination is
    /// [`Program::full_width_regs`].
    pub fn pointwise(&self) -> bool {
        match self {
            Instr::Copy { .. }
            | Instr::Arith { .. }
            | Instr::Neg { .. }
            | Instr::Promote { .. }
            | Instr::Dot { .. }
            | Instr::Cross { .. }
            | Instr::Compare { .. }
            | Instr::And { .. }
            | Instr::Or { .. }
            | Instr::Not { .. }
            | Instr::Select { .. }
            | Instr::MakeTriple { .. } => true,
            Instr::Call { f, .. } => f.pointwise(),
            _ => false,
        }
    }

    /// The destination of a pointwise instruction.
    pub fn pointwise_dst(&self) -> Option<Reg> {
        if !self.pointwise() {
            return None;
        }
        match self {
            Instr::Copy { dst, .. }
            | Instr::Arith { dst, .. }
            | Instr::Neg { dst, .. }
            | Instr::Promote { dst, .. }
            | Instr::Dot { dst, .. }
            | Instr::Cross { dst, .. }
            | Instr::Compare { dst, .. }
            | Instr::And { dst, .. }
            | Instr::Or { dst, .. }
            | Instr::Not { dst, .. }
            | Instr::Select { dst, .. }
            | Instr::MakeTriple { dst, .. }
            | Instr::Call { dst, .. } => Some(*dst),
            _ => None,
        }
    }
}

impl Program {
    /// Registers that must hold a value at every point, not only at the points running when
    /// they were computed: what a sparse mask's pointwise instructions leave alone must never
    /// be read. A register is full width when
    /// - an instruction that is not pointwise reads it (derivatives read neighbours, many
    ///   built-ins read a varying argument's first value, illuminance compares positions
    ///   everywhere), other than a masked store (`Mov`, which reads running points) and the
    ///   condition of an `if` or loop;
    /// - it is read where its definition may not have run for the same points: before its
    ///   definition in program order, or outside the block (and the blocks nested in it)
    ///   where it is defined, or it is defined in two blocks;
    /// - a pointwise instruction writes it and so does a masked store or another
    ///   instruction (a variable, not a temporary);
    /// - a pointwise instruction with a full-width destination reads it.
    pub fn full_width_regs(&self) -> Vec<bool> {
        let n = self.regs.len();
        let mut full = vec![false; n];
        // Pass 1: who writes what.
        let mut pw_def = vec![false; n];
        let mut other_def = vec![false; n];
        fn writers(
            code: &[Instr],
            pw_def: &mut [bool],
            other_def: &mut [bool],
            regs: &mut Vec<Reg>,
        ) {
            for ins in code {
                match ins.pointwise_dst() {
                    Some(d) => {
                        if let Some(x) = pw_def.get_mut(d as usize) {
                            *x = true;
                        }
                    }
                    None => match ins {
                        Instr::Mov { dst, .. } => {
                            if let Some(x) = other_def.get_mut(*dst as usize) {
                                *x = true;
                            }
                        }
                        Instr::If { .. }
                        | Instr::Loop { .. }
                        | Instr::Break(_)
                        | Instr::Continue(_)
                        | Instr::Return
                        | Instr::Function { .. } => {}
                        // Anything else may write any register it names.
                        other => {
                            regs.clear();
                            instr_regs(other, regs);
                            for &r in regs.iter() {
                                if let Some(x) = other_def.get_mut(r as usize) {
                                    *x = true;
                                }
                            }
                        }
                    },
                }
                for block in nested(ins) {
                    writers(block, pw_def, other_def, regs);
                }
            }
        }
        let mut regs = Vec::new();
        writers(&self.init, &mut pw_def, &mut other_def, &mut regs);
        writers(&self.body, &mut pw_def, &mut other_def, &mut regs);
        for r in 0..n {
            if pw_def[r] && other_def[r] {
                full[r] = true;
            }
        }
        // Pass 2: reads, in program order, with the chain of enclosing blocks.
        struct Walk<'f> {
            full: &'f mut [bool],
            pw_def: &'f [bool],
            def_block: Vec<usize>,
            stack: Vec<usize>,
            blocks: usize,
            regs: Vec<Reg>,
        }
        impl Walk<'_> {
            fn read(&mut self, r: Reg) {
                let r = r as usize;
                if r >= self.full.len() || !self.pw_def[r] {
                    return;
                }
                let b = self.def_block[r];
                if b == usize::MAX || !self.stack.contains(&b) {
                    self.full[r] = true;
                }
            }
            fn block(&mut self, code: &[Instr], loop_cond: Option<Reg>) {
                self.blocks += 1;
                self.stack.push(self.blocks);
                for ins in code {
                    self.regs.clear();
                    instr_regs(ins, &mut self.regs);
                    let regs = std::mem::take(&mut self.regs);
                    match ins.pointwise_dst() {
                        Some(d) => {
                            for &r in regs.iter().filter(|&&r| r != d) {
                                self.read(r);
                            }
                            let me = *self.stack.last().unwrap_or(&0);
                            if let Some(b) = self.def_block.get_mut(d as usize) {
                                if *b != usize::MAX && *b != me {
                                    self.full[d as usize] = true;
                                }
                                *b = me;
                            }
                        }
                        None => match ins {
                            Instr::Mov { src, .. } => self.read(*src),
                            // The condition is read where it was computed (the loop's
                            // condition code runs first in the loop), at running points.
                            Instr::If { cond, .. } => self.read(*cond),
                            Instr::Loop { .. } => {}
                            _ => {
                                for &r in &regs {
                                    if let Some(x) = self.full.get_mut(r as usize) {
                                        *x = true;
                                    }
                                }
                            }
                        },
                    }
                    self.regs = regs;
                    match ins {
                        Instr::Loop {
                            cond_code,
                            cond,
                            body,
                            step,
                            ..
                        } => {
                            self.block(cond_code, Some(*cond));
                            self.block(body, None);
                            self.block(step, None);
                        }
                        _ => {
                            for b in nested(ins) {
                                self.block(b, None);
                            }
                        }
                    }
                }
                if let Some(c) = loop_cond {
                    self.read(c);
                }
                self.stack.pop();
            }
        }
        let mut w = Walk {
            full: &mut full,
            pw_def: &pw_def,
            def_block: vec![usize::MAX; n],
            stack: Vec::new(),
            blocks: 0,
            regs: Vec::new(),
        };
        w.block(&self.init, None);
        w.block(&self.body, None);
        // Pass 3: a full-width result needs its operands at every point too.
        fn close(code: &[Instr], full: &mut [bool], regs: &mut Vec<Reg>, changed: &mut bool) {
            for ins in code {
                if let Some(d) = ins.pointwise_dst() {
                    if full.get(d as usize).copied().unwrap_or(false) {
                        regs.clear();
                        instr_regs(ins, regs);
                        for &r in regs.iter() {
                            if let Some(x) = full.get_mut(r as usize) {
                                if !*x {
                                    *x = true;
                                    *changed = true;
                                }
                            }
                        }
                    }
                }
                for b in nested(ins) {
                    close(b, full, regs, changed);
                }
            }
        }
        loop {
            let mut changed = false;
            close(&self.init, &mut full, &mut regs, &mut changed);
            close(&self.body, &mut full, &mut regs, &mut changed);
            if !changed {
                break;
            }
        }
        full
    }

    /// Marks the loops that may run compacted: once few of a grid's points are still in a
    /// loop (a march whose points leave at different steps), the interpreter gathers the
    /// registers the loop names at those points into a grid of just them, runs the rest of
    /// the loop there at full vector width, and scatters the values back. A loop qualifies
    /// when everything in it is a masked store, control flow, or a pointwise computation
    /// (see [`Instr::pointwise`]) whose destination is not [`Program::full_width_regs`]
    /// (so no value at a point that left the loop is ever read: the same results as running
    /// over the whole grid), and no `break`, `continue` or `return` leaves it. Needs
    /// `full_width` computed.
    pub fn mark_compact_loops(&mut self) {
        fn walk(code: &mut [Instr], full: &[bool]) {
            for ins in code.iter_mut() {
                let compact_regs = compact_loop_regs(ins, full);
                match ins {
                    Instr::Loop {
                        cond_code,
                        body,
                        step,
                        compact,
                        ..
                    } => {
                        walk(cond_code, full);
                        walk(body, full);
                        walk(step, full);
                        *compact = compact_regs;
                    }
                    Instr::If {
                        then, otherwise, ..
                    } => {
                        walk(then, full);
                        walk(otherwise, full);
                    }
                    Instr::Function { body }
                    | Instr::Illuminance { body, .. }
                    | Instr::Illuminate { body, .. }
                    | Instr::Solar { body, .. } => walk(body, full),
                    Instr::Gather {
                        body, otherwise, ..
                    } => {
                        walk(body, full);
                        walk(otherwise, full);
                    }
                    _ => {}
                }
            }
        }
        let full = std::mem::take(&mut self.full_width);
        walk(&mut self.init, &full);
        walk(&mut self.body, &full);
        self.full_width = full;
    }

    /// Registers whose value may be moved (not copied) into the destination of the one `Mov`
    /// that reads them: compiler temporaries named exactly twice in the whole program (their
    /// one definition and that `Mov`), defined by a computation rather than a move, and not
    /// a parameter, global, constant or array element. The interpreter uses this to skip
    /// whole-grid copies of `var = expr` when every point is running.
    pub fn movable_temps(&self) -> Vec<bool> {
        let n = self.regs.len();
        let mut count = vec![0u32; n];
        let mut mov_src = vec![false; n];
        let mut mov_dst = vec![false; n];
        let mut pinned = vec![false; n];
        let mut regs = Vec::new();
        // The block each register was last named in: a temporary defined in one block and
        // moved in another (say, before a loop and inside it) must keep being copied.
        let mut block_of = vec![usize::MAX; n];
        let mut blocks = 0usize;
        #[allow(clippy::too_many_arguments)]
        fn walk(
            code: &[Instr],
            regs: &mut Vec<Reg>,
            count: &mut [u32],
            mov_src: &mut [bool],
            mov_dst: &mut [bool],
            pinned: &mut [bool],
            block_of: &mut [usize],
            blocks: &mut usize,
        ) {
            *blocks += 1;
            let me = *blocks;
            for ins in code {
                regs.clear();
                instr_regs(ins, regs);
                for &r in regs.iter() {
                    if let Some(c) = count.get_mut(r as usize) {
                        *c += 1;
                        let b = &mut block_of[r as usize];
                        if *b != usize::MAX && *b != me {
                            pinned[r as usize] = true;
                        }
                        *b = me;
                    }
                }
                match ins {
                    Instr::Mov { dst, src } | Instr::Copy { dst, src } => {
                        let is_mov = matches!(ins, Instr::Mov { .. });
                        if let Some(s) = mov_src.get_mut(*src as usize) {
                            *s |= is_mov;
                        }
                        if let Some(d) = mov_dst.get_mut(*dst as usize) {
                            *d = true;
                        }
                        if !is_mov {
                            if let Some(p) = pinned.get_mut(*src as usize) {
                                *p = true;
                            }
                        }
                    }
                    Instr::GetIndex { base, len, .. } | Instr::SetIndex { base, len, .. } => {
                        for r in *base..*base + *len {
                            if let Some(p) = pinned.get_mut(r as usize) {
                                *p = true;
                            }
                        }
                    }
                    _ => {}
                }
                for block in nested(ins) {
                    walk(
                        block, regs, count, mov_src, mov_dst, pinned, block_of, blocks,
                    );
                }
            }
        }
        walk(
            &self.init,
            &mut regs,
            &mut count,
            &mut mov_src,
            &mut mov_dst,
            &mut pinned,
            &mut block_of,
            &mut blocks,
        );
        walk(
            &self.body,
            &mut regs,
            &mut count,
            &mut mov_src,
            &mut mov_dst,
            &mut pinned,
            &mut block_of,
            &mut blocks,
        );
        for p in &self.params {
            let len = p.array.unwrap_or(1).max(1) as Reg;
            for r in p.reg..p.reg + len {
                if let Some(x) = pinned.get_mut(r as usize) {
                    *x = true;
                }
            }
        }
        for g in &self.globals {
            if let Some(x) = pinned.get_mut(g.reg as usize) {
                *x = true;
            }
        }
        for (r, _) in &self.consts {
            if let Some(x) = pinned.get_mut(*r as usize) {
                *x = true;
            }
        }
        (0..n)
            .map(|r| count[r] == 2 && mov_src[r] && !mov_dst[r] && !pinned[r])
            .collect()
    }
}
