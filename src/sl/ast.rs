//! The shading-language syntax tree, as parsed (before name resolution and type checking).
//!
//! Every node carries the [`Span`] it was parsed from (already mapped through the
//! preprocessor to the original file and line).

use crate::diag::Span;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ShaderKind {
    Surface,
    Displacement,
    Light,
    Volume,
    Imager,
    Transformation,
}

impl ShaderKind {
    pub const ALL: [ShaderKind; 6] = [
        ShaderKind::Surface,
        ShaderKind::Displacement,
        ShaderKind::Light,
        ShaderKind::Volume,
        ShaderKind::Imager,
        ShaderKind::Transformation,
    ];

    pub fn name(self) -> &'static str {
        match self {
            ShaderKind::Surface => "surface",
            ShaderKind::Displacement => "displacement",
            ShaderKind::Light => "light",
            ShaderKind::Volume => "volume",
            ShaderKind::Imager => "imager",
            ShaderKind::Transformation => "transformation",
        }
    }

    /// The RIB request that names a shader of this kind.
    pub fn request(self) -> &'static str {
        match self {
            ShaderKind::Surface => "Surface",
            ShaderKind::Displacement => "Displacement",
            ShaderKind::Light => "LightSource",
            ShaderKind::Volume => "Atmosphere",
            ShaderKind::Imager => "Imager",
            ShaderKind::Transformation => "Deformation",
        }
    }
}

/// The base types of the language.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BaseType {
    Float,
    String,
    Color,
    Point,
    Vector,
    Normal,
    Matrix,
    Void,
}

impl BaseType {
    pub fn name(self) -> &'static str {
        match self {
            BaseType::Float => "float",
            BaseType::String => "string",
            BaseType::Color => "color",
            BaseType::Point => "point",
            BaseType::Vector => "vector",
            BaseType::Normal => "normal",
            BaseType::Matrix => "matrix",
            BaseType::Void => "void",
        }
    }
    /// point, vector, normal or color: three floats.
    pub fn is_triple(self) -> bool {
        matches!(
            self,
            BaseType::Color | BaseType::Point | BaseType::Vector | BaseType::Normal
        )
    }
    /// point, vector or normal.
    pub fn is_spatial(self) -> bool {
        matches!(self, BaseType::Point | BaseType::Vector | BaseType::Normal)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Detail {
    Uniform,
    Varying,
}

/// Array-ness of a declaration.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ArraySpec {
    /// `x[n]`
    Sized(usize),
    /// `x[]` (shader parameters and function formals only)
    Unsized,
}

/// A written type: `[uniform|varying] base`; the array part belongs to each declared name.
#[derive(Clone, Debug, PartialEq)]
pub struct TypeSpec {
    pub detail: Option<Detail>,
    pub base: BaseType,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub struct SourceFile {
    pub items: Vec<Item>,
}

#[derive(Clone, Debug, PartialEq)]
pub enum Item {
    Shader(ShaderDef),
    Function(FuncDef),
}

#[derive(Clone, Debug, PartialEq)]
pub struct ShaderDef {
    pub kind: ShaderKind,
    pub name: String,
    pub name_span: Span,
    pub params: Vec<Formal>,
    pub body: Block,
    pub span: Span,
}

/// A shader parameter or a function formal. Shader parameters always have a default.
#[derive(Clone, Debug, PartialEq)]
pub struct Formal {
    pub output: bool,
    pub ty: TypeSpec,
    pub name: String,
    pub array: Option<ArraySpec>,
    pub default: Option<Expr>,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub struct FuncDef {
    pub ret: TypeSpec,
    pub name: String,
    pub name_span: Span,
    pub params: Vec<Formal>,
    pub body: Block,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Block {
    pub stmts: Vec<Stmt>,
    pub span: Span,
}

/// One name in a variable declaration: `a`, `b[3] = {…}`, `c = 1`.
#[derive(Clone, Debug, PartialEq)]
pub struct VarInit {
    pub name: String,
    pub array: Option<ArraySpec>,
    pub init: Option<Expr>,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Stmt {
    pub kind: StmtKind,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub enum StmtKind {
    /// `[extern] [output] type name [= init], …;`
    VarDecl {
        is_extern: bool,
        output: bool,
        ty: TypeSpec,
        vars: Vec<VarInit>,
    },
    /// A nested function definition.
    Function(FuncDef),
    Expr(Expr),
    Block(Block),
    If {
        cond: Expr,
        then: Box<Stmt>,
        otherwise: Option<Box<Stmt>>,
    },
    While {
        cond: Expr,
        body: Box<Stmt>,
    },
    For {
        init: Option<Expr>,
        cond: Option<Expr>,
        step: Option<Expr>,
        body: Box<Stmt>,
    },
    /// `break [n]`
    Break(u32),
    /// `continue [n]`
    Continue(u32),
    Return(Option<Expr>),
    /// `illuminance([category,] P [, axis, angle]) body`: `args` holds every argument as written.
    Illuminance {
        args: Vec<Expr>,
        body: Box<Stmt>,
    },
    /// `illuminate(P [, axis, angle]) body`
    Illuminate {
        args: Vec<Expr>,
        body: Box<Stmt>,
    },
    /// `solar([axis, angle]) body`
    Solar {
        args: Vec<Expr>,
        body: Box<Stmt>,
    },
    /// `gather(category, P, dir, angle, samples, …) body [else otherwise]`
    Gather {
        args: Vec<Expr>,
        body: Box<Stmt>,
        otherwise: Option<Box<Stmt>>,
    },
    Empty,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum UnOp {
    Neg,
    Not,
    Plus,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BinOp {
    Add,
    Sub,
    Mul,
    Div,
    /// `.` dot product
    Dot,
    /// `^` cross product
    Cross,
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
    And,
    Or,
}

impl BinOp {
    pub fn symbol(self) -> &'static str {
        match self {
            BinOp::Add => "+",
            BinOp::Sub => "-",
            BinOp::Mul => "*",
            BinOp::Div => "/",
            BinOp::Dot => ".",
            BinOp::Cross => "^",
            BinOp::Eq => "==",
            BinOp::Ne => "!=",
            BinOp::Lt => "<",
            BinOp::Le => "<=",
            BinOp::Gt => ">",
            BinOp::Ge => ">=",
            BinOp::And => "&&",
            BinOp::Or => "||",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum AssignOp {
    Set,
    Add,
    Sub,
    Mul,
    Div,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Expr {
    pub kind: ExprKind,
    pub span: Span,
}

#[derive(Clone, Debug, PartialEq)]
pub enum ExprKind {
    Float(f32),
    Str(String),
    Ident(String),
    /// `a[i]` (also a texture channel: `texture(name[1], …)`)
    Index {
        base: Box<Expr>,
        index: Box<Expr>,
    },
    /// `f(args)`
    Call {
        name: String,
        name_span: Span,
        args: Vec<Expr>,
    },
    /// `(a, b, c)` or a 16-tuple: a triple or matrix whose type comes from its context.
    Tuple(Vec<Expr>),
    /// `{a, b, c}`: an array initialiser.
    ArrayLit(Vec<Expr>),
    /// `type ["space"] expr`: typecasts and constructors (`color "hsv" (h,s,v)`,
    /// `point "world" (0,0,0)`, `matrix "shader" 1`, `float x`).
    Cast {
        ty: BaseType,
        space: Option<String>,
        expr: Box<Expr>,
    },
    Unary {
        op: UnOp,
        expr: Box<Expr>,
    },
    Binary {
        op: BinOp,
        lhs: Box<Expr>,
        rhs: Box<Expr>,
    },
    Ternary {
        cond: Box<Expr>,
        then: Box<Expr>,
        otherwise: Box<Expr>,
    },
    /// `target op= value`; target is an `Ident` or an `Index`. `x++`/`++x` parse as `x += 1`.
    Assign {
        op: AssignOp,
        target: Box<Expr>,
        value: Box<Expr>,
    },
}
