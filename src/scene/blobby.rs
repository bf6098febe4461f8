//! `Blobby` (RISpec 3.2 §5.7): the code array decoded into a field program.
//!
//! Input: a checked `Blobby nleaf [code] [floats] [strings]` call. Output: a
//! [`BlobbyProgram`] (plain data, object space) in `Geometry::Blobby`, or diagnostics.
//! Invariants: every operand of an operator names an earlier instruction, every float and
//! string index is in range, and the program's value is that of its last instruction. Leaves
//! (the primitive fields 1000–1003) are numbered in the order they appear; their count is the
//! element count of the varying/vertex primitive-variable classes.
//!
//! Opcodes (RISpec Table 5.3): 1000 constant, 1001 ellipsoid (16-float matrix), 1002 segment
//! (start, end, radius, matrix: 23 floats), 1003 repelling plane (depth-map string, 4 floats);
//! operators 0 add, 1 multiply, 2 maximum, 3 minimum (count, then operands), 4 subtract,
//! 5 divide (two operands), 6 negate, 7 identity (one operand). PRMan's App Note #31 swaps 4
//! and 5; Aqsis and RISpec agree on 4 = subtract, which is what arbor does.

use glam::{Mat4, Vec3};

use crate::diag::Diag;

use super::builder::Builder;
use super::params::{Counts, ParamUse};
use super::table::{mat_from_rib, Call};
use super::types::Geometry;

/// The field value at which the surface lies (RISpec; a lone ellipsoid blob with the identity
/// matrix is the sphere of radius ½, since (1 − ¼)³ = 27/64).
pub const BLOBBY_THRESHOLD: f32 = 0.421875;

/// One instruction of the field program.
#[derive(Clone, Debug, PartialEq)]
pub enum BlobOp {
    Constant(f32),
    /// The unit-sphere field carried by `object_from_blob`.
    Ellipsoid(Mat4),
    /// A capsule around the segment `a`–`b` of radius `radius`, in the space of `m`.
    Segment {
        a: Vec3,
        b: Vec3,
        radius: f32,
        m: Mat4,
    },
    /// A repelling ground plane read from a depth map (the map's name and A B C D).
    Repulsion {
        depthmap: String,
        params: [f32; 4],
    },
    Add(Vec<u32>),
    Multiply(Vec<u32>),
    Max(Vec<u32>),
    Min(Vec<u32>),
    Subtract(u32, u32),
    Divide(u32, u32),
    Negate(u32),
    Identity(u32),
}

impl BlobOp {
    pub fn is_leaf(&self) -> bool {
        matches!(
            self,
            BlobOp::Constant(_)
                | BlobOp::Ellipsoid(_)
                | BlobOp::Segment { .. }
                | BlobOp::Repulsion { .. }
        )
    }
    /// The instructions this one reads.
    pub fn operands(&self) -> Vec<u32> {
        match self {
            BlobOp::Add(v) | BlobOp::Multiply(v) | BlobOp::Max(v) | BlobOp::Min(v) => v.clone(),
            BlobOp::Subtract(a, b) | BlobOp::Divide(a, b) => vec![*a, *b],
            BlobOp::Negate(a) | BlobOp::Identity(a) => vec![*a],
            _ => Vec::new(),
        }
    }
}

/// A decoded Blobby: instructions in order, the last one is the field.
#[derive(Clone, Debug, PartialEq)]
pub struct BlobbyProgram {
    /// `nleaf` as given (the primitive-variable element count).
    pub nleaf: usize,
    pub ops: Vec<BlobOp>,
}

impl BlobbyProgram {
    /// Leaf number of each instruction (None for operators).
    pub fn leaf_numbers(&self) -> Vec<Option<usize>> {
        let mut n = 0;
        self.ops
            .iter()
            .map(|op| {
                op.is_leaf().then(|| {
                    n += 1;
                    n - 1
                })
            })
            .collect()
    }
}

/// What went wrong decoding, and which positional argument to point at.
pub struct DecodeError {
    pub arg: usize,
    pub message: String,
    pub help: &'static str,
}

/// Decodes the code array (see the module docs). Warnings (unused leaves) are returned as
/// messages beside the program.
pub fn decode(
    nleaf: i64,
    code: &[i64],
    floats: &[f32],
    strings: &[String],
) -> Result<(BlobbyProgram, Vec<String>), DecodeError> {
    let err = |arg: usize, message: String, help: &'static str| DecodeError { arg, message, help };
    const OPS_HELP: &str = "each instruction is an opcode and its operands: 1000 f, 1001 f, 1002 f, 1003 s f (leaves: float/string indices), 0–3 n i…, 4–5 i j, 6–7 i (operators: earlier instruction numbers)";
    if nleaf < 0 {
        return Err(err(
            0,
            format!("nleaf is {nleaf}; it must be at least 0"),
            "nleaf is the number of primitive fields (opcodes 1000–1003) in the code",
        ));
    }
    let mut ops: Vec<BlobOp> = Vec::new();
    let mut plugins: Vec<String> = Vec::new();
    let mut c = 0usize;
    let word = |at: usize, what: &str, ninstr: usize| -> Result<i64, DecodeError> {
        code.get(at).copied().ok_or_else(|| {
            err(
                1,
                format!(
                    "instruction {ninstr} needs {what}, but the code array ends after {} numbers",
                    code.len()
                ),
                OPS_HELP,
            )
        })
    };
    let float_at = |idx: i64, n: usize, ninstr: usize| -> Result<&[f32], DecodeError> {
        let i = usize::try_from(idx)
            .ok()
            .filter(|&i| i.checked_add(n).is_some_and(|e| e <= floats.len()));
        match i {
            Some(i) => Ok(&floats[i..i + n]),
            None => Err(err(
                2,
                format!("instruction {ninstr} reads {n} floats from index {idx}, but the float array holds {}", floats.len()),
                "float operands index the third argument (0-based)",
            )),
        }
    };
    while c < code.len() {
        let n = ops.len();
        let opcode = code[c];
        c += 1;
        let operand = |v: i64| -> Result<u32, DecodeError> {
            if v >= 0 && (v as usize) < n {
                Ok(v as u32)
            } else {
                Err(err(
                    1,
                    format!("instruction {n} (opcode {opcode}) uses instruction {v}, which is not an earlier instruction (0–{})", n as i64 - 1),
                    "operators combine instructions given before them, numbered from 0 in code order",
                ))
            }
        };
        let op = match opcode {
            1000 => {
                let f = float_at(word(c, "a float index", n)?, 1, n)?;
                c += 1;
                BlobOp::Constant(f[0])
            }
            1001 => {
                let f = float_at(word(c, "a float index", n)?, 16, n)?;
                c += 1;
                BlobOp::Ellipsoid(mat_from_rib(f))
            }
            1002 => {
                let f = float_at(word(c, "a float index", n)?, 23, n)?;
                c += 1;
                BlobOp::Segment {
                    a: Vec3::from_slice(&f[0..3]),
                    b: Vec3::from_slice(&f[3..6]),
                    radius: f[6],
                    m: mat_from_rib(&f[7..23]),
                }
            }
            1003 => {
                let s = word(c, "a string index", n)?;
                let fi = word(c + 1, "a float index", n)?;
                c += 2;
                let name = usize::try_from(s).ok().and_then(|i| strings.get(i)).ok_or_else(|| {
                    err(
                        3,
                        format!("instruction {n} (repelling plane) names string {s}, but the string array holds {}", strings.len()),
                        "the depth map's name is an index into the fourth argument (0-based)",
                    )
                })?;
                let f = float_at(fi, 4, n)?;
                BlobOp::Repulsion {
                    depthmap: name.clone(),
                    params: [f[0], f[1], f[2], f[3]],
                }
            }
            0..=3 => {
                let count = word(c, "an operand count", n)?;
                c += 1;
                if count < 1 || count as usize > code.len() {
                    return Err(err(1, format!("instruction {n} (opcode {opcode}) has an operand count of {count}"), OPS_HELP));
                }
                let mut v = Vec::with_capacity(count as usize);
                for k in 0..count as usize {
                    v.push(operand(word(c + k, "an operand", n)?)?);
                }
                c += count as usize;
                match opcode {
                    0 => BlobOp::Add(v),
                    1 => BlobOp::Multiply(v),
                    2 => BlobOp::Max(v),
                    _ => BlobOp::Min(v),
                }
            }
            4 | 5 => {
                let a = operand(word(c, "two operands", n)?)?;
                let b = operand(word(c + 1, "two operands", n)?)?;
                c += 2;
                if opcode == 4 {
                    BlobOp::Subtract(a, b)
                } else {
                    BlobOp::Divide(a, b)
                }
            }
            6 | 7 => {
                let a = operand(word(c, "an operand", n)?)?;
                c += 1;
                if opcode == 6 {
                    BlobOp::Negate(a)
                } else {
                    BlobOp::Identity(a)
                }
            }
            1004.. => {
                // A field plug-in (PRMan 1004: name, nfloat, float index, nstring, string
                // index; Air's 9000: an operand count, then name and data indices): a DSO
                // arbor cannot load. It stays a leaf (it is counted by nleaf) whose field is
                // zero, so the rest of the surface still renders.
                let operands = if opcode == 1004 {
                    5
                } else {
                    let count = word(c, "an operand count", n)?;
                    c += 1;
                    usize::try_from(count)
                        .ok()
                        .filter(|&k| c + k <= code.len())
                        .ok_or_else(|| err(1, format!("instruction {n} (opcode {opcode}) has an operand count of {count}"), OPS_HELP))?
                };
                let first = word(c, "a plug-in name index", n)?;
                c += operands;
                let plugin = usize::try_from(first)
                    .ok()
                    .and_then(|i| strings.get(i))
                    .map_or_else(|| format!("opcode {opcode}"), |s| format!("`{s}`"));
                plugins.push(format!(
                    "instruction {n} is a field plug-in ({plugin}), a compiled DSO arbor cannot load; its field is left out (zero)"
                ));
                BlobOp::Constant(0.0)
            }
            other => {
                return Err(err(
                    1,
                    format!("instruction {n} has unknown opcode {other}"),
                    "Blobby opcodes: 1000 constant, 1001 ellipsoid, 1002 segment, 1003 repelling plane, 1004 and up field plug-ins, 0 add, 1 multiply, 2 max, 3 min, 4 subtract, 5 divide, 6 negate, 7 identity",
                ))
            }
        };
        ops.push(op);
    }
    if ops.is_empty() {
        return Err(err(
            1,
            "the code array holds no instruction".into(),
            OPS_HELP,
        ));
    }
    let mut warnings = plugins;
    let leaves = ops.iter().filter(|o| o.is_leaf()).count();
    if leaves != nleaf as usize {
        warnings.push(format!(
            "nleaf is {nleaf} but the code holds {leaves} primitive fields; varying values are counted by nleaf"
        ));
    }
    // Leaves the last instruction never reads do not shape the surface.
    let mut used = vec![false; ops.len()];
    used[ops.len() - 1] = true;
    for i in (0..ops.len()).rev() {
        if used[i] {
            for o in ops[i].operands() {
                used[o as usize] = true;
            }
        }
    }
    let unused: Vec<String> = ops
        .iter()
        .enumerate()
        .filter(|(i, o)| o.is_leaf() && !used[*i])
        .map(|(i, _)| i.to_string())
        .collect();
    if !unused.is_empty() {
        warnings.push(format!(
            "instruction(s) {} do not reach the last instruction, which is the field; they have no effect",
            unused.join(", ")
        ));
    }
    Ok((
        BlobbyProgram {
            nleaf: nleaf as usize,
            ops,
        },
        warnings,
    ))
}

impl Builder<'_> {
    pub(super) fn blobby(&mut self, call: &Call<'_>) {
        if !self.geometry_wanted(call) {
            return;
        }
        let nleaf = call.pos[0].int();
        let decoded = decode(
            nleaf,
            call.pos[1].ints(),
            call.pos[2].floats(),
            call.pos[3].strs(),
        );
        let (program, warnings) = match decoded {
            Ok(p) => p,
            Err(e) => {
                let d = Diag::error("scene::blobby", format!("`Blobby`: {}", e.message))
                    .label(call.pos_spans[e.arg], "here")
                    .help(e.help);
                self.report(d);
                return;
            }
        };
        for w in warnings {
            self.report(
                Diag::warning("scene::blobby", format!("`Blobby`: {w}"))
                    .label(call.pos_spans[1], "this code"),
            );
        }
        let pv = self.params(call, ParamUse::Primitive);
        let n = program.nleaf;
        let c = Counts {
            uniform: 1,
            varying: n,
            vertex: n,
            facevarying: n,
            facevertex: n,
        };
        self.finish_prim(call, Geometry::Blobby(std::sync::Arc::new(program)), pv, c);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const I: [f32; 16] = [
        1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.,
    ];

    #[test]
    fn decodes_leaves_and_operators() {
        let mut f = I.to_vec();
        f.extend_from_slice(&I);
        f[16 + 12] = 1.0; // second blob moved along x
        let (p, w) = decode(2, &[1001, 0, 1001, 16, 0, 2, 0, 1], &f, &[])
            .ok()
            .unwrap();
        assert!(w.is_empty());
        assert_eq!(p.ops.len(), 3);
        assert_eq!(p.ops[2], BlobOp::Add(vec![0, 1]));
        match &p.ops[1] {
            BlobOp::Ellipsoid(m) => assert_eq!(m.transform_point3(Vec3::ZERO), Vec3::X),
            other => panic!("{other:?}"),
        }
        assert_eq!(p.leaf_numbers(), vec![Some(0), Some(1), None]);
    }

    #[test]
    fn rejects_forward_references_and_bad_indices() {
        let e = decode(1, &[0, 2, 0, 1, 1001, 0], &I, &[]).err().unwrap();
        assert!(
            e.message.contains("not an earlier instruction"),
            "{}",
            e.message
        );
        let e = decode(1, &[1001, 3], &I, &[]).err().unwrap();
        assert_eq!(e.arg, 2);
        let e = decode(1, &[1003, 0, 0], &I, &[]).err().unwrap();
        assert_eq!(e.arg, 3);
        let e = decode(1, &[1001], &I, &[]).err().unwrap();
        assert!(e.message.contains("ends after"));
        let e = decode(1, &[999, 0], &I, &[]).err().unwrap();
        assert!(e.message.contains("unknown opcode 999"));
    }

    #[test]
    fn field_plugins_are_zero_leaves_with_a_warning() {
        // Aqsis's examples/features/blobby/air/blobplane.rib: five ellipsoids and Air's
        // plug-in plane `9000 4 0 80 1 96` (operand count 4), all six added.
        let mut f: Vec<f32> = (0..5).flat_map(|_| I).collect();
        f.extend_from_slice(&I);
        f.push(2.0);
        let code = [
            1001, 0, 1001, 16, 1001, 32, 1001, 48, 1001, 64, 9000, 4, 0, 80, 1, 96, 0, 6, 0, 1, 2,
            3, 4, 5,
        ];
        let (p, w) = decode(6, &code, &f, &["dbo_plane".into()]).ok().unwrap();
        assert_eq!(p.ops.len(), 7);
        assert_eq!(p.ops[5], BlobOp::Constant(0.0));
        assert_eq!(p.ops[6], BlobOp::Add(vec![0, 1, 2, 3, 4, 5]));
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].contains("`dbo_plane`"), "{}", w[0]);
        // PRMan's 1004: name, nfloat, float index, nstring, string index.
        let (p, w) = decode(
            2,
            &[1001, 0, 1004, 0, 0, 0, 0, 0, 0, 2, 0, 1],
            &I,
            &["fieldplug".into()],
        )
        .ok()
        .unwrap();
        assert_eq!(p.ops[1], BlobOp::Constant(0.0));
        assert_eq!(p.ops[2], BlobOp::Add(vec![0, 1]));
        assert!(w[0].contains("`fieldplug`"), "{w:?}");
    }

    #[test]
    fn warns_about_unused_leaves_and_leaf_count() {
        let mut f = I.to_vec();
        f.extend_from_slice(&I);
        let (_, w) = decode(3, &[1001, 0, 1001, 16], &f, &[]).ok().unwrap();
        assert_eq!(w.len(), 2, "{w:?}");
    }
}
