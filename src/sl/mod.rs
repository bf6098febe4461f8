//! The RenderMan Shading Language compiler: preprocess → parse → check → compile.
//!
//! Input: `.sl` source. Output: a `Program` for the shading runtime.

pub mod ast;
pub mod parse;
