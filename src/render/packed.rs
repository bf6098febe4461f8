//! Diced grids packed while they wait for their surface shader.
//!
//! Input: a diced, displaced [`Grid`]. Output: a [`PackedGrid`] holding the same values in
//! less memory, and back the identical grid (bit for bit, whatever was in it).
//! Invariants: a per-point column is kept as is, or as one value repeated when every point
//! has the same bits, or as a reference to an earlier column with the same bits (N and Ng,
//! I and P, s and u, t and v often coincide); unpacking rebuilds each column exactly.
//!
//! Why: grids are shaded only when a bucket first sees them (hidden ones never are), so a
//! diced grid may wait a whole bucket row or more; packed it holds about half the memory
//! (colour, opacity and the copies are the columns most often constant or repeated).

use glam::Vec3;

use crate::pool::{self, Pooled};
use crate::shade::Grid;

/// One per-point column of a waiting grid (`nu` points a row).
#[derive(Debug)]
enum Col<T> {
    Each(Vec<T>),
    /// Every point the same value (`usize` points).
    Same(T, usize),
    /// One value per grid row: every point of row `j` has the bits of `rows[j]` (u-only
    /// variation is absent: v, dPdu of a bilinear patch).
    PerRow(Vec<T>),
    /// One value per grid column: every row has the bits of the first (u, dPdv of a bilinear
    /// patch).
    PerColumn(Vec<T>),
    /// The same bits as the column it was packed against.
    Like,
}

/// Plain values made of `WORDS` f32s and nothing else, compared by their bits (so −0 and
/// NaNs survive the round trip).
///
/// # Safety
/// Implementors must be `repr(C)` (or primitive) with exactly `WORDS` f32 fields and no
/// padding: their slices are read as `u32` words.
unsafe trait Bits: Copy {
    const WORDS: usize;
}

unsafe impl Bits for f32 {
    const WORDS: usize = 1;
}

// glam's Vec3 is `#[repr(C)] { x, y, z: f32 }` (Vec3A is the padded one).
unsafe impl Bits for Vec3 {
    const WORDS: usize = 3;
}
const _: () = assert!(std::mem::size_of::<Vec3>() == 12 && std::mem::align_of::<Vec3>() == 4);

/// The bits of `v`, as words.
fn words<T: Bits>(v: &[T]) -> &[u32] {
    // SAFETY: `Bits` types are `WORDS` f32s without padding (so every byte is initialised
    // and u32-aligned), and the slice covers exactly `v`'s memory.
    unsafe { std::slice::from_raw_parts(v.as_ptr().cast::<u32>(), v.len() * T::WORDS) }
}

/// Whether `a` and `b` hold the same bits (a memcmp: the packing runs on every diced grid).
fn same_bits<T: Bits>(a: &[T], b: &[T]) -> bool {
    words(a) == words(b)
}

impl<T: Bits + Pooled> Col<T> {
    /// `v`, as a reference when it has the bits of `like`, else as [`Col::pack`] does.
    /// (Columns not kept as they are go back to this thread's buffer pool.)
    fn pack_like(v: Vec<T>, like: &[T], nu: usize, nv: usize) -> Col<T> {
        if !v.is_empty() && same_bits(&v, like) {
            pool::give(v);
            Col::Like
        } else {
            Col::pack(v, nu, nv)
        }
    }

    /// `v` (`nv` rows of `nu` points) in the smallest of the forms that keep its bits: one value,
    /// one per row, one per column, or every point. Each test stops at the first point that
    /// breaks it, so a column that varies both ways costs little more than a look.
    fn pack(v: Vec<T>, nu: usize, nv: usize) -> Col<T> {
        let n = v.len();
        if n == 0 {
            return Col::Each(v);
        }
        if same_bits(&v[1..], &v[..n - 1]) {
            let x = v[0];
            pool::give(v);
            return Col::Same(x, n);
        }
        // The row and column forms rebuild `nu × nv` points: only for columns of that size.
        if nu == 0 || n != nu * nv {
            return Col::Each(v);
        }
        // Every row equal to the one before it: the first row, repeated.
        if n > nu && same_bits(&v[nu..], &v[..n - nu]) {
            let row = pool::copied(&v[..nu]);
            pool::give(v);
            return Col::PerColumn(row);
        }
        if nu > 1 && v.chunks_exact(nu).all(|r| same_bits(&r[1..], &r[..nu - 1])) {
            let mut rows = pool::take(n / nu);
            rows.extend(v.iter().step_by(nu).copied());
            pool::give(v);
            return Col::PerRow(rows);
        }
        Col::Each(v)
    }

    /// The column again (`n` = `nu × nv` points in the row and column forms); `like` is the
    /// unpacked column it was packed against. Rebuilt columns come from this thread's buffer
    /// pool, and the packed rows go back to it.
    fn unpack(self, like: &[T], nu: usize, n: usize) -> Vec<T> {
        match self {
            Col::Each(v) => v,
            Col::Same(x, n) => pool::filled(n, x),
            Col::PerRow(rows) => {
                let mut out = pool::take(n);
                for &x in &rows {
                    out.resize(out.len() + nu, x);
                }
                pool::give(rows);
                out
            }
            Col::PerColumn(row) => {
                let mut out = pool::take(n);
                while out.len() < n {
                    out.extend_from_slice(&row);
                }
                pool::give(row);
                out
            }
            Col::Like => pool::copied(like),
        }
    }

    /// Gives a column's buffer back to this thread's pool (a grid dropped unshaded).
    fn recycle(self) {
        if let Col::Each(v) | Col::PerRow(v) | Col::PerColumn(v) = self {
            pool::give(v);
        }
    }

    fn bytes(&self) -> usize {
        match self {
            Col::Each(v) | Col::PerRow(v) | Col::PerColumn(v) => v.len() * std::mem::size_of::<T>(),
            Col::Same(..) | Col::Like => 0,
        }
    }
}

/// A diced grid, packed (see the module invariants).
#[derive(Debug)]
pub struct PackedGrid {
    /// The grid with its packed columns taken out (left empty).
    rest: Grid,
    p: Col<Vec3>,
    ng: Col<Vec3>,
    n: Col<Vec3>,
    dpdu: Col<Vec3>,
    dpdv: Col<Vec3>,
    u: Col<f32>,
    v: Col<f32>,
    s: Col<f32>,
    t: Col<f32>,
    cs: Col<Vec3>,
    os: Col<Vec3>,
    i: Col<Vec3>,
    ci: Col<Vec3>,
    oi: Col<Vec3>,
}

impl PackedGrid {
    pub fn pack(mut g: Grid) -> PackedGrid {
        let (nu, nv) = (g.nu, g.nv);
        let take3 = |v: &mut Vec<Vec3>| std::mem::take(v);
        let take1 = |v: &mut Vec<f32>| std::mem::take(v);
        let p = take3(&mut g.p);
        let ng = take3(&mut g.ng);
        let u = take1(&mut g.u);
        let v = take1(&mut g.v);
        let n = Col::pack_like(take3(&mut g.n), &ng, nu, nv);
        let i = Col::pack_like(take3(&mut g.i), &p, nu, nv);
        let s = Col::pack_like(take1(&mut g.s), &u, nu, nv);
        let t = Col::pack_like(take1(&mut g.t), &v, nu, nv);
        PackedGrid {
            p: Col::pack(p, nu, nv),
            ng: Col::pack(ng, nu, nv),
            n,
            dpdu: Col::pack(take3(&mut g.dpdu), nu, nv),
            dpdv: Col::pack(take3(&mut g.dpdv), nu, nv),
            u: Col::pack(u, nu, nv),
            v: Col::pack(v, nu, nv),
            s,
            t,
            cs: Col::pack(take3(&mut g.cs), nu, nv),
            os: Col::pack(take3(&mut g.os), nu, nv),
            i,
            ci: Col::pack(take3(&mut g.ci), nu, nv),
            oi: Col::pack(take3(&mut g.oi), nu, nv),
            rest: g,
        }
    }

    /// The grid as it was packed.
    pub fn unpack(self) -> Grid {
        let mut g = self.rest;
        let (nu, n) = (g.nu, g.nu * g.nv);
        g.p = self.p.unpack(&[], nu, n);
        g.ng = self.ng.unpack(&[], nu, n);
        g.u = self.u.unpack(&[], nu, n);
        g.v = self.v.unpack(&[], nu, n);
        g.n = self.n.unpack(&g.ng, nu, n);
        g.i = self.i.unpack(&g.p, nu, n);
        g.s = self.s.unpack(&g.u, nu, n);
        g.t = self.t.unpack(&g.v, nu, n);
        g.cs = self.cs.unpack(&[], nu, n);
        g.os = self.os.unpack(&[], nu, n);
        g.ci = self.ci.unpack(&[], nu, n);
        g.oi = self.oi.unpack(&[], nu, n);
        g.dpdu = self.dpdu.unpack(&[], nu, n);
        g.dpdv = self.dpdv.unpack(&[], nu, n);
        g
    }

    /// Gives the buffers back to this thread's pool (a grid never shaded: every bucket that
    /// could see it found it hidden).
    pub fn recycle(self) {
        for c in [
            self.p, self.ng, self.n, self.dpdu, self.dpdv, self.cs, self.os, self.i, self.ci,
            self.oi,
        ] {
            c.recycle();
        }
        for c in [self.u, self.v, self.s, self.t] {
            c.recycle();
        }
        self.rest.recycle();
    }

    /// Approximate heap size, for the memory statistic.
    pub fn bytes(&self) -> usize {
        let cols3 = [
            &self.p, &self.ng, &self.n, &self.dpdu, &self.dpdv, &self.cs, &self.os, &self.i,
            &self.ci, &self.oi,
        ];
        let cols1 = [&self.u, &self.v, &self.s, &self.t];
        let motion = self
            .rest
            .motion
            .as_ref()
            .map_or(0, |m| m.p.iter().map(|k| k.len() * 12).sum::<usize>());
        let vars: usize = self.rest.primvars.iter().map(|v| v.floats.len() * 4).sum();
        cols3.iter().map(|c| c.bytes()).sum::<usize>()
            + cols1.iter().map(|c| c.bytes()).sum::<usize>()
            + motion
            + vars
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bits(g: &Grid) -> Vec<u32> {
        let mut out = vec![g.nu as u32, g.nv as u32, g.du.to_bits(), g.dv.to_bits()];
        for c in [
            &g.p, &g.n, &g.ng, &g.dpdu, &g.dpdv, &g.cs, &g.os, &g.i, &g.ci, &g.oi,
        ] {
            out.push(c.len() as u32);
            out.extend(c.iter().flat_map(|v| v.to_array()).map(f32::to_bits));
        }
        for c in [&g.u, &g.v, &g.s, &g.t] {
            out.push(c.len() as u32);
            out.extend(c.iter().map(|x| x.to_bits()));
        }
        out
    }

    #[test]
    fn packing_gives_back_the_same_bits_and_saves_the_repeated_columns() {
        let (nu, nv) = (5, 4);
        let mut g = Grid::with_size(nu, nv);
        for k in 0..nu * nv {
            let x = k as f32 * 0.37 - 2.0;
            g.p[k] = Vec3::new(x, -x * 0.5, 3.0 + x * x);
            g.ng[k] = Vec3::new(0.0, -0.0, 1.0 + k as f32);
            g.dpdu[k] = Vec3::new(1.0, k as f32, 0.0);
            g.dpdv[k] = Vec3::Y;
            g.u[k] = (k % nu) as f32 / 4.0;
            g.v[k] = (k / nu) as f32 / 3.0;
        }
        g.n = g.ng.clone();
        g.i = g.p.clone();
        g.s = g.u.clone();
        g.t = g.v.iter().map(|v| 1.0 - v).collect();
        // −0 against +0 and a NaN: compared by bits, not by value.
        g.cs[3] = Vec3::new(-0.0, 1.0, 1.0);
        g.os[0] = Vec3::new(f32::NAN, 1.0, 1.0);
        g.du = 0.25;
        let want = bits(&g);
        let packed = PackedGrid::pack(g.clone());
        // p, ng, dpdu, cs and os are kept whole; u one value per column, v and t one per
        // row; dpdv one value; n, i, s, ci and oi none.
        let n = nu * nv;
        assert_eq!(packed.bytes(), n * 12 * 5 + 4 * nu + 4 * nv * 2);
        assert!(matches!(packed.n, Col::Like) && matches!(packed.i, Col::Like));
        assert!(
            matches!(packed.s, Col::Like) && matches!(&packed.t, Col::PerRow(r) if r.len() == nv)
        );
        assert!(matches!(&packed.u, Col::PerColumn(r) if r.len() == nu));
        assert!(matches!(packed.dpdv, Col::Same(..)) && matches!(packed.dpdu, Col::Each(_)));
        assert!(matches!(packed.ci, Col::Same(..)) && matches!(packed.oi, Col::Same(..)));
        assert!(matches!(packed.cs, Col::Each(_)) && matches!(packed.os, Col::Each(_)));
        assert_eq!(bits(&packed.unpack()), want);
        // An empty grid round-trips too.
        let e = Grid::default();
        assert_eq!(bits(&PackedGrid::pack(e.clone()).unpack()), bits(&e));
    }

    #[test]
    fn rows_and_columns_pack_only_when_every_point_agrees() {
        let (nu, nv) = (4, 3);
        let per_row: Vec<f32> = (0..nu * nv).map(|k| (k / nu) as f32).collect();
        let per_col: Vec<f32> = (0..nu * nv).map(|k| (k % nu) as f32).collect();
        let mut one_off = per_row.clone();
        one_off[nu * 2 + 3] = -0.0;
        let mut one_off_col = per_col.clone();
        // +0 against −0 in the last row: the same value, not the same bits.
        one_off_col[nu * 2] = -0.0;
        for (v, want_bytes) in [
            (per_row.clone(), 4 * nv),
            (per_col.clone(), 4 * nu),
            (one_off, 4 * nu * nv),
            (one_off_col, 4 * nu * nv),
            // A column not of the grid's size is kept whole.
            (per_row[..nu * 2].to_vec(), 4 * nu * 2),
        ] {
            let c = Col::pack(v.clone(), nu, nv);
            assert_eq!(c.bytes(), want_bytes);
            let back = c.unpack(&[], nu, nu * nv);
            assert_eq!(words(&back), words(&v));
        }
    }
}
