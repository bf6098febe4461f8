//! The RenderMan Shading Language compiler: preprocess → parse → check → compile.
//!
//! Input: `.sl` source (files on the shader search path or the embedded standard library).
//! Output: [`ir::Program`]s for the shading runtime, cached by name in a [`ShaderLibrary`].

pub mod ast;
pub mod builtins;
pub mod foreign;
pub mod initials;
pub mod ir;
pub mod library;
pub mod lower;
pub mod parse;
pub mod preprocess;
pub mod rsl2;

pub use library::{compile_source, CompileOptions, ShaderLibrary};
