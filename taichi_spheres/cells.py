"""Cell arithmetic of the uniform grid: pure ti.funcs on cell coordinates.

A mixin of :class:`taichi_spheres.grid.Grid`, which holds the fields these functions
read: ``lo``, ``inv_cell``, ``cell`` (() vec3 real [m], [1/m], [m]), ``dims`` (() vec3
i32 cells per axis), ``start`` ((M+1,) i32 cell starts in ``order``) and ``periodic``
(3 Python bools, compiled in). Cell coordinates are vec3 i32 (x, y, z); a linear cell
index is ``(cx * ny + cy) * nz + cz``, so the cells of one z row are contiguous.
"""

import taichi as ti

__all__ = ["CellArithmetic"]


class CellArithmetic:
    """Cell coordinates of points, linear indices, periodic shifts, stencil rows,
    faces within reach and pair ownership (all static in the bound geometry)."""

    @ti.func
    def coords_of_position(self, p):
        """Cell coordinates (vec3 i32) of a point p [m], clamped into the grid."""
        f = (p - self.lo[None]) * self.inv_cell[None]
        dims = self.dims[None]
        c = ti.Vector([0, 0, 0])
        for a in ti.static(range(3)):
            c[a] = ti.min(ti.max(ti.cast(ti.floor(f[a]), ti.i32), 0), dims[a] - 1)
        return c

    @ti.func
    def linear(self, c):
        """Linear index (i32) of cell c (vec3 i32): ``(cx * ny + cy) * nz + cz``."""
        dims = self.dims[None]
        return (c[0] * dims[1] + c[1]) * dims[2] + c[2]

    @ti.func
    def coords(self, k):
        """Cell coordinates (vec3 i32) of the linear cell index k (inverse of linear)."""
        dims = self.dims[None]
        nz = dims[2]
        ny = dims[1]
        return ti.Vector([k // (ny * nz), (k // nz) % ny, k % nz])

    @ti.func
    def shifted(self, c, off):
        """Cell c + off (vec3 i32), wrapped on periodic axes; valid=False off the grid."""
        out = c + off
        valid = True
        dims = self.dims[None]
        for a in ti.static(range(3)):
            n = dims[a]
            if ti.static(self.periodic[a]):
                if out[a] < 0:
                    out[a] += n
                elif out[a] >= n:
                    out[a] -= n
            else:
                if out[a] < 0 or out[a] >= n:
                    valid = False
        return out, valid

    @ti.func
    def row_ranges(self, c, row):
        """Ranges [a0, b0) and [a1, b1) of ``order`` holding the cells
        (c.x + row.x, c.y + row.y, c.z + row.z .. c.z + row.w); empty when off the grid."""
        a0 = 0
        b0 = 0
        a1 = 0
        b1 = 0
        xy, ok = self.shifted(c, ti.Vector([row[0], row[1], 0]))
        if ok:
            dims = self.dims[None]
            nz = dims[2]
            base = (xy[0] * dims[1] + xy[1]) * nz
            z0 = c[2] + row[2]
            z1 = c[2] + row[3]
            if ti.static(self.periodic[2]):
                if z0 < 0:
                    a1 = self.start[base + nz - 1]
                    b1 = self.start[base + nz]
                    z0 = 0
                if z1 >= nz:
                    a1 = self.start[base]
                    b1 = self.start[base + 1]
                    z1 = nz - 1
            else:
                z0 = ti.max(z0, 0)
                z1 = ti.min(z1, nz - 1)
            if z0 <= z1:
                a0 = self.start[base + z0]
                b0 = self.start[base + z1 + 1]
        return a0, b0, a1, b1

    @ti.func
    def corner(self, c):
        """Lower corner of cell c (vec3 i32) [m]."""
        return self.lo[None] + c * self.cell[None]

    @ti.func
    def sides_within(self, f, reach):
        """For a point at offset f [m] from the lower corner of its cell (minimum image:
        see Contacts.min_image), which neighbours across the cell's faces lie within
        ``reach`` [m]: (lower, upper), vec3 i32 of 0/1 per axis. A point farther than
        reach from a face is at least that far from everything a sphere binned beyond
        it can reach after it moved."""
        lower = ti.Vector([0, 0, 0])
        upper = ti.Vector([0, 0, 0])
        cell = self.cell[None]
        for a in ti.static(range(3)):
            if f[a] < reach:
                lower[a] = 1
            if f[a] > cell[a] - reach:
                upper[a] = 1
        return lower, upper

    @ti.func
    def owner(self, ca, cb):
        """Component-wise lower cell of two equal-or-adjacent cells (periodic-aware)."""
        out = ca
        dims = self.dims[None]
        for a in ti.static(range(3)):
            if ca[a] != cb[a]:
                if ti.static(self.periodic[a]):
                    n = dims[a]
                    if (ca[a] + 1) % n != cb[a]:
                        out[a] = cb[a]
                elif cb[a] < ca[a]:
                    out[a] = cb[a]
        return out

    @ti.func
    def forward(self, ci, cj, p, q):
        """Whether the forward scan (FORWARD_ROWS) from the sphere at slot p, in cell ci,
        reaches the sphere at slot q, in the equal-or-adjacent cell cj: the offset
        cj - ci (wrapped into -1..1 on periodic axes) is lexicographically positive,
        or zero with q after p."""
        off = cj - ci
        dims = self.dims[None]
        for a in ti.static(range(3)):
            if ti.static(self.periodic[a]):
                n = dims[a]
                if off[a] > 1:
                    off[a] -= n
                elif off[a] < -1:
                    off[a] += n
        out = q > p
        if off[0] != 0:
            out = off[0] > 0
        elif off[1] != 0:
            out = off[1] > 0
        elif off[2] != 0:
            out = off[2] > 0
        return out
