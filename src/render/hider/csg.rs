//! Constructive solid geometry resolved per sample (RISpec §5.6, `SolidBegin`).
//!
//! Input: the scene's [`SolidNode`]s and, per sample, every hit of CSG geometry in front of the
//! sample's nearest opaque non-CSG surface, each knowing its primitive solid (leaf), the
//! root of its tree and whether the ray enters or leaves the leaf there (front- or back-facing
//! against the leaf's outward normal). Output: the hits that lie on the boundary of their
//! tree's solid — the only ones the hider keeps.
//! Invariants: along the sample's ray a point is inside a primitive solid when the leaf's last
//! hit before it entered the solid or its next hit beyond it leaves it. On a closed surface the
//! two agree; where a sample slips through a crack between grids (or sees a hit twice) the
//! solid still counts as entered, so the front shows through a crack in the back and the far
//! side through a crack in the front, as without CSG. The eye may be inside a solid. A hit is
//! visible when its tree's inside/outside state flips there. Primitives placed directly in a boolean block
//! are each a primitive solid of their own. Non-CSG geometry never comes here.

use crate::scene::{Scene, SolidOp};

/// The CSG trees of a scene.
#[derive(Clone, Debug, Default)]
pub struct CsgTree {
    ops: Vec<SolidOp>,
    children: Vec<Vec<u32>>,
}

/// Where a primitive sits in the CSG trees.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CsgPrim {
    /// Its primitive solid (a leaf node).
    pub leaf: u32,
    /// The top of its tree.
    pub root: u32,
    /// Its surfaces bound the result from the other side (an odd number of "subtracted"
    /// positions on the way to the root): normals are flipped to face out of the result.
    pub inverted: bool,
}

impl CsgTree {
    /// The trees of `scene` and, per primitive, its place in them (None outside CSG).
    pub fn new(scene: &Scene) -> (CsgTree, Vec<Option<CsgPrim>>) {
        let mut ops: Vec<SolidOp> = scene.solids.iter().map(|n| n.op).collect();
        let mut parent: Vec<Option<u32>> = scene.solids.iter().map(|n| n.parent).collect();
        let mut per_prim = Vec::with_capacity(scene.primitives.len());
        for p in &scene.primitives {
            let Some(s) = p.attributes.solid.filter(|&s| (s as usize) < ops.len()) else {
                per_prim.push(None);
                continue;
            };
            let leaf = if ops[s as usize] == SolidOp::Primitive {
                s
            } else {
                // A surface directly in a boolean block: a primitive solid of its own.
                ops.push(SolidOp::Primitive);
                parent.push(Some(s));
                (ops.len() - 1) as u32
            };
            per_prim.push(Some(leaf));
        }
        let mut children = vec![Vec::new(); ops.len()];
        for (i, p) in parent.iter().enumerate() {
            if let Some(p) = p {
                children[*p as usize].push(i as u32);
            }
        }
        let tree = CsgTree { ops, children };
        let places = per_prim
            .into_iter()
            .map(|leaf| {
                leaf.map(|leaf| {
                    let mut inverted = false;
                    let mut at = leaf;
                    while let Some(p) = parent[at as usize] {
                        if tree.ops[p as usize] == SolidOp::Difference
                            && tree.children[p as usize].first() != Some(&at)
                        {
                            inverted = !inverted;
                        }
                        at = p;
                    }
                    CsgPrim {
                        leaf,
                        root: at,
                        inverted,
                    }
                })
            })
            .collect();
        (tree, places)
    }

    pub fn is_empty(&self) -> bool {
        self.ops.is_empty()
    }

    /// Whether `node` contains the ray point, given whether it is inside each leaf.
    fn inside(&self, node: u32, state: &[(u32, bool)]) -> bool {
        let n = node as usize;
        let kids = &self.children[n];
        match self.ops[n] {
            SolidOp::Primitive => {
                state.iter().any(|&(l, i)| l == node && i)
                    || kids.iter().any(|&k| self.inside(k, state))
            }
            SolidOp::Union => kids.iter().any(|&k| self.inside(k, state)),
            SolidOp::Intersection => {
                !kids.is_empty() && kids.iter().all(|&k| self.inside(k, state))
            }
            SolidOp::Difference => match kids.split_first() {
                Some((&first, rest)) => {
                    self.inside(first, state) && !rest.iter().any(|&k| self.inside(k, state))
                }
                None => false,
            },
        }
    }
}

/// One CSG surface seen by one sample.
#[derive(Clone, Copy, Debug)]
pub struct CsgHit {
    pub sample: u32,
    pub z: f32,
    pub key: u64,
    pub sub: u32,
    pub leaf: u32,
    pub root: u32,
    pub entering: bool,
    /// Index of the hider's own record of this hit (colour, opacity, output variables).
    pub payload: u32,
}

/// Sorts `hits` by sample and depth and calls `keep` with each hit on its solid's boundary.
pub fn resolve(tree: &CsgTree, hits: &mut [CsgHit], mut keep: impl FnMut(&CsgHit)) {
    hits.sort_unstable_by(|a, b| {
        a.sample
            .cmp(&b.sample)
            .then(a.z.total_cmp(&b.z))
            .then(a.key.cmp(&b.key))
            .then(a.sub.cmp(&b.sub))
    });
    let mut leaves: Vec<u32> = Vec::new();
    let mut inside: Vec<bool> = Vec::new();
    let mut state: Vec<(u32, bool)> = Vec::new();
    let mut start = 0;
    while start < hits.len() {
        let s = hits[start].sample;
        let end = start + hits[start..].iter().take_while(|h| h.sample == s).count();
        let run = &hits[start..end];
        leaves.clear();
        for h in run {
            if !leaves.contains(&h.leaf) {
                leaves.push(h.leaf);
            }
        }
        // inside[p·L + l]: leaf l holds the points between hits p − 1 and p, when its last
        // hit before them entered it or its next hit after them leaves it.
        let (n, nl) = (run.len(), leaves.len());
        inside.clear();
        inside.resize((n + 1) * nl, false);
        for (li, &l) in leaves.iter().enumerate() {
            let mut prev = false;
            for (p, h) in run.iter().enumerate() {
                inside[p * nl + li] = prev;
                if h.leaf == l {
                    prev = h.entering;
                }
            }
            inside[n * nl + li] = prev;
            let mut next = false;
            for p in (0..n).rev() {
                let h = &run[p];
                if h.leaf == l {
                    next = !h.entering;
                }
                inside[p * nl + li] |= next;
            }
        }
        let solid_at = |p: usize, root: u32, state: &mut Vec<(u32, bool)>| {
            state.clear();
            state.extend(
                leaves
                    .iter()
                    .enumerate()
                    .map(|(li, &l)| (l, inside[p * nl + li])),
            );
            tree.inside(root, state)
        };
        for (p, h) in run.iter().enumerate() {
            if solid_at(p, h.root, &mut state) != solid_at(p + 1, h.root, &mut state) {
                keep(h);
            }
        }
        start = end;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Attributes, Geometry, ParamList, Primitive, SolidNode};
    use std::sync::Arc;

    fn scene(solids: &[(SolidOp, Option<u32>)], prim_solids: &[u32]) -> Scene {
        let mut s = Scene::default();
        for &(op, parent) in solids {
            s.solids.push(SolidNode {
                op,
                parent,
                span: crate::diag::Span::new(0, 0, 0),
            });
        }
        for &p in prim_solids {
            s.primitives.push(Primitive {
                geometry: Arc::new(Geometry::Named { name: "x".into() }),
                primvars: Arc::new(ParamList::default()),
                attributes: Arc::new({
                    let mut a = Attributes::default();
                    a.solid = Some(p);
                    a
                }),
                world_from_object: glam::Mat4::IDENTITY.into(),
                span: crate::diag::Span::new(0, 0, 0),
                motion: None,
            });
        }
        s
    }

    fn hit(z: f32, leaf: u32, entering: bool, payload: u32) -> CsgHit {
        CsgHit {
            sample: 0,
            z,
            key: 0,
            sub: payload,
            leaf,
            root: 0,
            entering,
            payload,
        }
    }

    fn visible(tree: &CsgTree, hits: &mut [CsgHit]) -> Vec<u32> {
        let mut v = Vec::new();
        resolve(tree, hits, |h| v.push(h.payload));
        v
    }

    use SolidOp::*;

    #[test]
    fn difference_shows_the_cut_face_of_the_subtracted_solid() {
        // A − B along one ray: enter B at 1, enter A at 2, leave B at 3, leave A at 4.
        let s = scene(
            &[
                (Difference, None),
                (Primitive, Some(0)),
                (Primitive, Some(0)),
            ],
            &[1, 2],
        );
        let (t, places) = CsgTree::new(&s);
        assert_eq!(places[0].unwrap().inverted, false);
        assert_eq!(places[1].unwrap().inverted, true);
        let mut h = [
            hit(1.0, 2, true, 0),
            hit(2.0, 1, true, 1),
            hit(3.0, 2, false, 2),
            hit(4.0, 1, false, 3),
        ];
        assert_eq!(visible(&t, &mut h), vec![2, 3]);
    }

    #[test]
    fn union_and_intersection_keep_the_outer_and_inner_boundaries() {
        let mut h = [
            hit(1.0, 1, true, 0),
            hit(2.0, 2, true, 1),
            hit(3.0, 1, false, 2),
            hit(4.0, 2, false, 3),
        ];
        let (u, _) = CsgTree::new(&scene(
            &[(Union, None), (Primitive, Some(0)), (Primitive, Some(0))],
            &[],
        ));
        assert_eq!(visible(&u, &mut h.clone()), vec![0, 3]);
        let (i, _) = CsgTree::new(&scene(
            &[
                (Intersection, None),
                (Primitive, Some(0)),
                (Primitive, Some(0)),
            ],
            &[],
        ));
        assert_eq!(visible(&i, &mut h), vec![1, 2]);
    }

    #[test]
    fn nested_difference_inverts_twice() {
        // A − (B − C): C's surfaces face out of the result as they are.
        let s = scene(
            &[
                (Difference, None),
                (Primitive, Some(0)),
                (Difference, Some(0)),
                (Primitive, Some(2)),
                (Primitive, Some(2)),
            ],
            &[1, 3, 4],
        );
        let (_, places) = CsgTree::new(&s);
        let inv: Vec<bool> = places.iter().map(|p| p.unwrap().inverted).collect();
        assert_eq!(inv, vec![false, true, false]);
    }

    #[test]
    fn loose_primitives_in_a_boolean_are_solids_of_their_own() {
        let s = scene(&[(Intersection, None)], &[0, 0]);
        let (t, places) = CsgTree::new(&s);
        let (a, b) = (places[0].unwrap(), places[1].unwrap());
        assert_ne!(a.leaf, b.leaf);
        assert_eq!((a.root, b.root), (0, 0));
        let mut h = [
            hit(1.0, a.leaf, true, 0),
            hit(2.0, b.leaf, true, 1),
            hit(3.0, a.leaf, false, 2),
            hit(4.0, b.leaf, false, 3),
        ];
        assert_eq!(visible(&t, &mut h), vec![1, 2]);
    }
}
