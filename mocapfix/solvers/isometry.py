"""Bone-length isometry energy and its Gauss–Newton step, batched over frames.

Yang et al. 2019 (IEEE TIP, "Spatio-temporal reconstruction for 3D motion recovery"),
eq. 5 and eqs. 16–20::

    E_iso(N) = Σ_t Σ_{bones (i,j)} r_tb²,   r_tb = ||n_i^t − n_j^t||² − l_b²

and the N-subproblem of their ADM-ALM (Algorithm 1, line 4)::

    δ = (γ JᵀJ + ρ I)⁻¹ (−Z − ρ (N − A) − γ Jᵀ F(N))

with J the Jacobian of the residual vector F. Each residual touches the two ends of one
bone in one frame, so ``γ JᵀJ + ρ I`` is block-diagonal by frame: T independent (3S × 3S)
systems (S joints). They are never assembled as one (3TS)² matrix. Two exact solvers,
both vectorised over frames:

* ``"tree"`` (used when the bones form a forest, as every skeleton does): the per-frame
  matrix has the sparsity of the skeleton tree (3 × 3 blocks, off-diagonal block
  ``−γ g gᵀ`` per bone with ``g = 2 (n_i − n_j)``), so block Gaussian elimination from the
  leaves to the root has no fill-in (Golub & Van Loan, *Matrix Computations*, §4.3 on
  banded/sparse Cholesky; the tree case is the "elimination tree" of George & Liu). It is a
  loop over joints, each step a batch of 3 × 3 solves over all frames.
* ``"dense"`` (any bone graph, e.g. marker pairs with cycles): the Woodbury identity
  ``(ρI + γJᵀJ)⁻¹ = ρ⁻¹ (I − Jᵀ (ρ/γ I + JJᵀ)⁻¹ J)`` turns each frame's system into a
  (B × B) one (B bones, fewer unknowns than 3S), solved by one batched
  ``np.linalg.solve`` over all frames, in chunks of frames to bound memory.

Layout: joint-major with time last, so that every operation runs on contiguous
length-T vectors: ``N`` is (S, 3, T) (``positions.transpose(1, 2, 0)`` of a Motion's
(T, S, 3)); ``bones`` a (B, 2) integer array of joint indices; ``lengths`` (B,) or (B, T)
target lengths, in the unit of ``N``. Jacobian rows ``g`` are (B, 3, T).
"""
from __future__ import annotations

import numpy as np


def bone_vectors(N: np.ndarray, bones: np.ndarray) -> np.ndarray:
    """``n_i − n_j`` for every bone and frame: (B, 3, T)."""
    bones = np.asarray(bones, dtype=np.intp).reshape(-1, 2)
    return N[bones[:, 0]] - N[bones[:, 1]]


def _lengths2(lengths) -> np.ndarray:
    sq = np.asarray(lengths, dtype=np.float64) ** 2
    return sq[:, None] if sq.ndim == 1 else sq


def residuals(N: np.ndarray, bones: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """``r_tb = ||n_i − n_j||² − l_b²`` (Yang 2019 eq. 5/16): (B, T)."""
    d = bone_vectors(N, bones)
    return np.einsum("bxt,bxt->bt", d, d) - _lengths2(lengths)


def energy(N: np.ndarray, bones: np.ndarray, lengths: np.ndarray) -> float:
    """``E_iso(N) = Σ r_tb²`` (Yang 2019 eq. 5)."""
    r = residuals(N, bones, lengths)
    return float(np.sum(r * r))


def incidence(bones: np.ndarray, n_joints: int) -> np.ndarray:
    """(S, B) signed incidence: +1 at the bone's first joint, −1 at its second. Row s of
    ``Jᵀ y`` is ``Σ_b inc[s, b] g_b y_b``."""
    bones = np.asarray(bones, dtype=np.intp).reshape(-1, 2)
    inc = np.zeros((n_joints, len(bones)))
    cols = np.arange(len(bones))
    np.add.at(inc, (bones[:, 0], cols), 1.0)
    np.add.at(inc, (bones[:, 1], cols), -1.0)
    return inc


def is_forest(bones: np.ndarray, n_joints: int) -> bool:
    """True when the bones, as undirected edges, have no cycle (and no self-loop)."""
    parent = list(range(n_joints))

    def root(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for i, j in np.asarray(bones, dtype=np.intp).reshape(-1, 2):
        ri, rj = root(int(i)), root(int(j))
        if ri == rj:
            return False
        parent[ri] = rj
    return True


class IsometrySystem:
    """The per-frame Gauss–Newton systems of one bone graph; build once, step many times.

    Parameters
    ----------
    bones : (B, 2) joint indices.
    n_joints : S.
    solver : "auto" (tree when the bones form a forest, else dense), "tree" or "dense".
    chunk : frames per batched dense solve (memory bound: chunk × B² floats).
    tree_chunk : frames per pass of the tree elimination (small enough to stay in cache).
    """

    def __init__(self, bones, n_joints: int, solver: str = "auto", chunk: int = 2048,
                 tree_chunk: int = 1024):
        self.bones = np.asarray(bones, dtype=np.intp).reshape(-1, 2)
        self.n_joints = int(n_joints)
        if len(self.bones) and (self.bones.min() < 0 or self.bones.max() >= n_joints):
            raise ValueError("bone index out of range")
        if np.any(self.bones[:, 0] == self.bones[:, 1]):
            raise ValueError("a bone joins a joint to itself")
        forest = is_forest(self.bones, n_joints)
        if solver == "auto":
            solver = "tree" if forest else "dense"
        if solver == "tree" and not forest:
            raise ValueError("the tree solver needs bones without cycles")
        if solver not in ("tree", "dense"):
            raise ValueError(f"unknown solver {solver!r}")
        self.solver = solver
        self.chunk = int(chunk)
        self.tree_chunk = int(tree_chunk)
        self.inc = incidence(self.bones, n_joints)
        # sparse copies: products with these tiny matrices must not go through a
        # multithreaded BLAS (slow and erratic on a busy machine)
        import scipy.sparse as sp   # imported here: listing the cleaners need not load it

        self._inc_sp = sp.csr_matrix(self.inc)
        self._abs_inc_sp = sp.csr_matrix(np.abs(self.inc))
        if solver == "tree":
            self._plan_tree()

    # -- pieces of the Gauss–Newton step ------------------------------------------------
    def jacobian_rows(self, N: np.ndarray) -> np.ndarray:
        """``g_tb = 2 (n_i − n_j)``, (B, 3, T): the Jacobian row of r_tb is +g at i, −g at j."""
        return 2.0 * bone_vectors(N, self.bones)

    def apply_jt(self, g: np.ndarray, y: np.ndarray) -> np.ndarray:
        """``Jᵀ y`` for y (B, T): (S, 3, T)."""
        B, _, T = g.shape
        gy = (g * y[:, None, :]).reshape(B, 3 * T)
        return (self._inc_sp @ gy).reshape(self.n_joints, 3, T)

    def apply_j(self, g: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``J v`` for v (S, 3, T): (B, T)."""
        dv = v[self.bones[:, 0]] - v[self.bones[:, 1]]
        return np.einsum("bxt,bxt->bt", g, dv)

    def apply_system(self, g: np.ndarray, v: np.ndarray, gamma: float, rho: float) -> np.ndarray:
        """``(γ JᵀJ + ρ I) v`` (for tests and checks)."""
        return gamma * self.apply_jt(g, self.apply_j(g, v)) + rho * v

    def solve(self, g: np.ndarray, rhs: np.ndarray, gamma: float, rho: float) -> np.ndarray:
        """Solve ``(γ JᵀJ + ρ I) δ = rhs`` frame by frame, all frames at once.

        ``g`` (B, 3, T) from :meth:`jacobian_rows`, ``rhs`` (S, 3, T); ``rho > 0``."""
        if rho <= 0:
            raise ValueError("rho must be positive")
        if gamma == 0 or len(self.bones) == 0:
            return rhs / rho
        if self.solver == "tree":
            # frames in chunks that stay in cache: the elimination is many small passes
            T = rhs.shape[2]
            if T <= self.tree_chunk:
                return self._solve_tree(g, rhs, gamma, rho)
            out = np.empty_like(rhs)
            for lo in range(0, T, self.tree_chunk):
                sl = slice(lo, lo + self.tree_chunk)
                out[..., sl] = self._solve_tree(g[..., sl], rhs[..., sl], gamma, rho)
            return out
        return self._solve_dense(g, rhs, gamma, rho)

    def step(self, N, A, Z, lengths, gamma: float, rho: float) -> np.ndarray:
        """The Gauss–Newton update δ of Yang 2019 eq. 20 / Algorithm 1 line 4:
        ``δ = (γJᵀJ + ρI)⁻¹ (−Z − ρ(N − A) − γ Jᵀ F(N))``. Arrays (S, 3, T); ``A`` or
        ``Z`` may be None (taken as N and 0: a damped Gauss–Newton step on E_iso alone)."""
        g = self.jacobian_rows(N)
        r = 0.25 * np.einsum("bxt,bxt->bt", g, g) - _lengths2(lengths)
        rhs = self.apply_jt(g, r)
        rhs *= -gamma
        if A is not None:
            rhs -= rho * (N - A)
        if Z is not None:
            rhs -= Z
        return self.solve(g, rhs, gamma, rho)

    def limit_step(self, N: np.ndarray, delta: np.ndarray, lengths) -> tuple[np.ndarray, int]:
        """``delta`` (S, 3, T) scaled down, frame by frame, so that no bone vector
        ``d = n_i − n_j`` changes by more than ``||d|| + l``; returns (step, frames scaled).

        Every solution of a bone's constraint ``||d|| = l`` lies within ``||d|| + l`` of
        the current ``d``, so a step that moves ``d`` farther overshoots all of them. The
        Gauss–Newton step of :meth:`step` does exactly that when a bone is compressed
        below a third of its length: linearising ``||d||² − l²`` at a short ``d`` gives a
        step of about ``(l² − ||d||²) / (2 ||d||)`` along ``d``, unbounded as ``||d|| → 0``
        (the bone's direction is then undefined), and the only damping is ρ — steps of
        metres for bones of centimetres under heavy noise, which the ALM then amplifies.
        The frame's whole step is scaled (its direction kept), as a damped Gauss–Newton
        step; frames where the bound holds are returned unchanged."""
        d = bone_vectors(N, self.bones)
        dd = bone_vectors(delta, self.bones)
        bound = np.sqrt(np.einsum("bxt,bxt->bt", d, d)) + np.sqrt(_lengths2(lengths))
        move = np.sqrt(np.einsum("bxt,bxt->bt", dd, dd))
        over = move > bound
        if not over.any():
            return delta, 0
        ratio = np.ones_like(move)
        ratio[over] = bound[over] / move[over]
        alpha = ratio.min(axis=0)                                        # (T,)
        return delta * alpha, int(np.count_nonzero(alpha < 1.0))

    # -- dense (Woodbury) -----------------------------------------------------------------
    def _solve_dense(self, g, rhs, gamma, rho):
        B = len(self.bones)
        # (JJᵀ)_{bc} = (Σ_s inc[s,b] inc[s,c]) g_b·g_c, nonzero only for bones sharing a joint
        share = self.inc.T @ self.inc
        eye = np.eye(B) * (rho / gamma)
        jb = self.apply_j(g, rhs)                                       # (B, T)
        y = np.empty_like(jb)
        gf = g.transpose(2, 1, 0)                                       # (T, 3, B)
        for lo in range(0, jb.shape[1], self.chunk):
            sl = slice(lo, lo + self.chunk)
            gg = np.matmul(gf[sl].transpose(0, 2, 1), gf[sl]) * share + eye
            y[:, sl] = np.linalg.solve(gg, jb[:, sl].T[..., None])[..., 0].T
        return (rhs - self.apply_jt(g, y)) / rho

    # -- tree (block elimination, no fill-in) -----------------------------------------------
    def _plan_tree(self):
        """Root every tree of the forest, then group the joints for elimination: deepest
        level first, and within a level into batches whose parents are distinct (so one
        batch updates each parent block once). Back-substitution goes level by level from
        the roots. Each batch is one vectorised step over all its joints and all frames."""
        S = self.n_joints
        adj: list[list[tuple[int, int]]] = [[] for _ in range(S)]
        for b, (i, j) in enumerate(self.bones):
            adj[i].append((j, b))
            adj[j].append((i, b))
        depth = np.full(S, -1)
        up, up_bone = np.full(S, -1), np.full(S, -1)
        for start in range(S):
            if depth[start] >= 0:
                continue
            depth[start] = 0
            queue = [start]
            for k in queue:                                   # breadth-first
                for nb, b in adj[k]:
                    if depth[nb] < 0:
                        depth[nb] = depth[k] + 1
                        up[nb], up_bone[nb] = k, b
                        queue.append(nb)
        self._up, self._up_bone = up, up_bone
        self._levels = [np.flatnonzero(depth == d) for d in range(int(depth.max()) + 1)]
        batches = []
        for nodes in self._levels[:0:-1]:                     # deepest level first, no roots
            rank = np.zeros(len(nodes), dtype=int)
            seen: dict[int, int] = {}
            for n, k in enumerate(nodes):
                rank[n] = seen.get(int(up[k]), 0)
                seen[int(up[k])] = rank[n] + 1
            batches += [nodes[rank == r] for r in range(int(rank.max()) + 1)]
        self._batches = batches

    def _solve_tree(self, g, rhs, gamma, rho):
        # The symmetric 3 × 3 blocks are kept as their 6 entries (xx, yy, zz, xy, xz, yz).
        S, _, T = rhs.shape
        gt = np.ascontiguousarray(g)                                     # (B, 3, T)
        gg = gamma * _sym_outer(gt)                                      # (B, 6, T)
        D = (self._abs_inc_sp @ gg.reshape(len(gt), -1)).reshape(S, 6, T)
        D[:, :3] += rho
        b = np.array(rhs, dtype=np.float64)                             # (S, 3, T), a copy
        u_all = np.empty((S, 3, T))                                     # D_k⁻¹ g_k
        w_all = np.empty((S, 3, T))                                     # D_k⁻¹ b_k (final b_k)
        for K in self._batches:                                         # eliminate leaves up
            P, bones = self._up[K], self._up_bone[K]
            gk = gt[bones]                                              # (k, 3, T)
            uw = _sym_solve(D[K], np.stack([gk, b[K]], axis=2))         # (k, 3, 2, T)
            u, w = uw[:, :, 0], uw[:, :, 1]
            u_all[K], w_all[K] = u, w
            s = np.einsum("kxt,kxt->kt", gk, u)
            D[P] -= (gamma * s)[:, None, :] * gg[bones]                 # γ² (gᵀD⁻¹g) g gᵀ
            b[P] += (gamma * np.einsum("kxt,kxt->kt", gk, w))[:, None, :] * gk   # γ g (gᵀD⁻¹b)
        roots = self._levels[0]
        x = np.empty_like(b)
        x[roots] = _sym_solve(D[roots], b[roots][:, :, None])[:, :, 0]
        for K in self._levels[1:]:                                      # back-substitute down
            # x_k = D_k⁻¹ (b_k + γ g (gᵀ x_p)) = D_k⁻¹ b_k + γ (gᵀ x_p) D_k⁻¹ g
            P, bones = self._up[K], self._up_bone[K]
            proj = np.einsum("kxt,kxt->kt", gt[bones], x[P])
            x[K] = w_all[K] + (gamma * proj)[:, None, :] * u_all[K]
        return x


def _sym_outer(v: np.ndarray) -> np.ndarray:
    """``v vᵀ`` of (k, 3, T) vectors as the 6 entries (xx, yy, zz, xy, xz, yz): (k, 6, T)."""
    out = np.empty((v.shape[0], 6, v.shape[2]))
    out[:, :3] = v * v
    out[:, 3:5] = v[:, :1] * v[:, 1:]
    out[:, 5] = v[:, 1] * v[:, 2]
    return out


def _sym_solve(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``m⁻¹ v`` for symmetric 3 × 3 matrices stored as (k, 6, T) entries (xx, yy, zz, xy,
    xz, yz) and vectors (k, 3, n, T), by the adjugate (Cramer's rule); the matrices here
    are ρI plus positive semidefinite terms, so det ≥ ρ³ > 0."""
    a, d, f, b, c, e = (m[:, i, None] for i in range(6))     # [[a b c] [b d e] [c e f]]
    i00 = d * f - e * e
    i01 = c * e - b * f
    i02 = b * e - c * d
    det = a * i00 + b * i01 + c * i02
    i11 = a * f - c * c
    i12 = b * c - a * e
    i22 = a * d - b * b
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    out = np.empty_like(v)
    out[:, 0] = (i00 * x + i01 * y + i02 * z) / det
    out[:, 1] = (i01 * x + i11 * y + i12 * z) / det
    out[:, 2] = (i02 * x + i12 * y + i22 * z) / det
    return out
