"""Options of mode isph: the porous ground (soil markers and drag constants, eq 9, 32), the pressure
Poisson solver, the projection's options; and the rules on the ground that need the tank and dx
(`check_ground`, run by Config)."""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal, Optional

from pydantic import Field, model_validator

from ..sph.support import SUPPORT_FACTOR
from .base import NonNegFloat, PosFloat, PosInt, Strict, fail
from .geometry import Shape

#: relative residual below which an f32 conjugate gradient stalls (rounding of b - A x)
F32_PPE_TOLERANCE = 1.0e-5


class SoilRegion(Shape):
    """A region of porous ground, filled with fixed soil markers (seed 000 section 4): a box or a mound
    (`Shape`)."""

    _noun: ClassVar[str] = "region"

    #: intrinsic porosity eps0 of the ground (1: no ground, the porous terms vanish)
    eps0: Annotated[float, Field(gt=0, le=1)]
    #: mean grain diameter D50 (m)
    d50: PosFloat


class Soil(Strict):
    """Porous ground of mode isph: fixed soil markers give each water particle its porosity (eq 32)
    and the drag coefficients a, b of eq 9c-d."""

    #: the ground, as regions of markers; a later region replaces earlier ones where they overlap
    regions: list[SoilRegion] = []
    #: marker spacing (m); default dx
    marker_spacing: Optional[PosFloat] = None
    #: cells: markers at cell centres, the ground surface lies on the region's faces; nodes: markers on
    #: the region's faces and corners too (the seed's 21 x 21 x 21 markers for a 20 cm cube at 1 cm),
    #: which moves the surface half a spacing outwards
    lattice: Literal["cells", "nodes"] = "cells"
    #: linear (Ergun-type) drag constant alpha_c of eq 9c
    alpha_c: PosFloat = 1000.0
    #: quadratic drag constant beta_c of eq 9d
    beta_c: NonNegFloat = 1.1


class PPESolver(Strict):
    #: sparse_cg: matrix assembled with ti.linalg.SparseMatrixBuilder, solved by SparseCG (Eigen CG
    #: on CPU); ell_pcg: matrix in ELL form in Taichi fields, Jacobi-preconditioned CG in Taichi
    #: kernels; mg_pcg: the same ELL matrix, CG preconditioned by a multigrid V-cycle on the
    #: neighbour grid's cells (iterations nearly independent of size: 1.7-4.7x faster steps in 2D
    #: from 10k to 200k particles, but 24 % slower on the 3D free fall of 8000; docs/performance.md)
    type: Literal["sparse_cg", "ell_pcg", "mg_pcg"] = "ell_pcg"
    #: relative residual |b - A p| / |b| to reach
    tolerance: PosFloat = 1.0e-8
    max_iterations: PosInt = 2000
    #: what to do when CG stops before the tolerance: stop the run, or record and go on
    on_failure: Literal["error", "warn"] = "error"
    #: ell_pcg and mg_pcg only: floats of the matrix and CG vectors; auto = f64 when the tolerance is below
    #: 1e-5 (f32 CG stalls near 1e-5 relative residual), else the run's precision
    precision: Literal["auto", "f32", "f64"] = "auto"
    #: ell_pcg and mg_pcg only: off-diagonal entries a row can hold (default: 1.5 x the kernel's lattice
    #: neighbour count, 30 in 2D and 84 in 3D, at most `neighbours.max`); a row that needs more
    #: widens the matrix during the run (with a warning)
    width: Optional[PosInt] = None

    @model_validator(mode="after")
    def _ell_keys(self):
        """The ELL-only keys need type ell_pcg or mg_pcg; f32 cannot reach a tolerance below 1e-5."""
        if self.type not in ("ell_pcg", "mg_pcg"):
            for key in ("precision", "width"):
                if key in self.model_fields_set:
                    fail(key, f"applies to isph.ppe.type ell_pcg and mg_pcg only (type is {self.type})")
        elif self.precision == "f32" and self.tolerance < F32_PPE_TOLERANCE:
            fail("precision", f"f32 conjugate gradient stalls near a relative residual of "
                 f"{F32_PPE_TOLERANCE:g}; raise isph.ppe.tolerance ({self.tolerance:g}) or use f64")
        return self


class ISPH(Strict):
    #: density-invariance stabilisation alpha of eq 30-31 (0 = divergence-free only)
    alpha: NonNegFloat = 0.01
    #: free-surface threshold N_surf of eq 34 (default: 48 in 3D as the seed, 17 in 2D)
    n_surf: Optional[PosInt] = None
    #: Dirichlet value at free-surface particles: zero (seed) or the hydrostatic pressure at the
    #: centre of a surface particle, rho_w |g| dx / 2 (the particle's top is the surface)
    free_surface_pressure: Literal["half_layer", "zero"] = "half_layer"
    #: free water (eps = 1) only: a particle below eq 34's count is free surface only if its number
    #: density <rho> is also below this fraction of rho_w (the MPS surface test of Koshizuka & Oka
    #: 1996, beta = 0.97). The count alone also flags particles inside the water whose outermost
    #: lattice ring (8 of 20 neighbours in 2D at 2.24 dx, r_e = 2.4 dx) has moved out; 0 = count only
    surface_density: Annotated[float, Field(ge=0, le=1)] = 0.97
    #: in and next to porous ground: a particle that eq 34's count (or, in free water, the plain
    #: particle count) finds short of neighbours is free surface only if no neighbour lies in a cone
    #: of this half-angle (degrees) about its outward normal, -sum_j V_j grad W_ij (the scan-region
    #: test of Marrone et al. 2010); 0 = eq 34's count alone (the seed's test). Eq 34 misreads the
    #: disordered pore water: it flagged 26-44 % of the permeameter's saturated plug and 15-25 % of
    #: the free fall's layer free surface, with 60 deg 0-1 % (docs/isph.md, "Surface test in the ground")
    ground_surface_cone: Annotated[float, Field(ge=0, lt=90)] = 60.0
    #: with the cone test: free water next to the ground (a candidate of that test, eps = 1) that the
    #: pressure equation solves below the atmosphere (P < 0) is free surface, and the equation is
    #: solved again (at most 3 times a step): air enters where water would be pulled apart. Without
    #: it, splashes over the free fall's layer, their cones blocked by the ground's water, held tensions
    #: of 10-150 kPa and threw water out of the tank (docs/isph.md, "Surface test in the ground")
    ground_surface_tension: bool = True
    #: with ground_surface_tension: pore water (eps < 1) joins that rule where its number density <rho>
    #: is below this fraction of its rest value (eps rho_w times its rest fill): ground that has
    #: drained part of its pores cannot hold its water in suction (coarse ground's air-entry value is
    #: some 0.1 kPa), while saturated pore water is left alone (a plug's exit face sits near zero
    #: pressure). Without it, water hung in the free fall's eps0 0.8 layer for seconds at 0.7-0.87 of
    #: its rest density under -0.5 to -2.8 kPa, and the volume measure ended +5..+7 % at dx 2 cm. 0 =
    #: free water only (docs/isph.md, "Air into drained pores")
    ground_tension_fill: Annotated[float, Field(ge=0, lt=1)] = 0.9
    #: with ground_surface_tension: a candidate held in tension that was free surface itself at the end
    #: of the last step is freed again, whether or not a free-surface particle is in its support (the
    #: air that was at it stays while the water there is pulled). Without it, a drop hanging under the
    #: free fall's layer in the tank's corners (its cones blocked by the walls it wets) lost every
    #: free-surface row in one step, was pulled at -182 kPa and the volume measure read +4.97 % for
    #: that step (dx 2 cm, dt 1 ms). false = air enters only from a free neighbour, the rule before
    #: (docs/isph.md, "Drained pore water a candidate of the cone")
    ground_tension_memory: bool = True
    #: the support over which eq 31's stabilisation reads the density of pore water (eps < 1):
    #: "particle", r_e, the seed's (and every other sum's); "pore", r_e eps^(-1/dim) (at most 2 r_e), the
    #: same support in units of the pore lattice's spacing, so that pore water is read over as many
    #: neighbours as free water. Over r_e a pore particle has 6-7 neighbours (2D, eps 0.4) and the
    #: reading depends on their arrangement: the permeameter's 10 mm plug held 0.97 or 1.03 of its pores
    #: at the same reading and its level split into branches 4.5 points apart over dt, and the coarse
    #: free fall's layer read 5 % above its fill (docs/isph.md, "The stabilisation over the pore
    #: lattice's support"). Its rest state at t = 0 is taken over the packing of the block the water
    #: was placed in (scene.packing). "interior": the pore support where it lies in uniform ground (every
    #: water particle within it of the particle's own porosity), r_e elsewhere: water crossing eq 32's
    #: ramp into the ground, pressed at the free water's spacing, is read over r_e (with "pore" the
    #: 5 mm plug held 1.015-1.021 of its pores, with "interior" 1.008-1.014; docs/isph.md, "The pore
    #: support in uniform ground only")
    ground_density_support: Literal["particle", "pore", "interior"] = "particle"
    #: with the cone test: pore water (eps < 1) whose <rho> is below ground_tension_fill of its rest value
    #: is a candidate of that test, whatever eq 34's count says. A front that enters dry ground as a sheet
    #: at the free water's spacing passes the count, which is scaled to the pore lattice, and as an
    #: interior row its deficit was pulled on by eq 31's term at a pressure growing as alpha / dt^2: the
    #: free fall's eps0 0.8 front (dx 1 cm) arrived at 0.206 s at dt 0.5 ms against 0.245 s at 1 ms (the
    #: 1D front of the seed's equations: 0.250 s; now 0.255 / 0.257 s). The cone still decides, so
    #: saturated pore water and a plug's face are not flagged. false = the count's candidates alone
    #: (docs/isph.md, "Drained pore water a candidate of the cone")
    ground_drained_candidate: bool = True
    #: with the cone test (ground_surface_cone > 0), in and next to porous ground: a particle whose
    #: number density <rho> is below this fraction of its rest value (eps rho_w) is free surface
    #: whatever its cone. Ground that drains holds its water in scattered pores with air between
    #: them: such a particle has neighbours all round and no empty cone, and as an interior row its
    #: deficit became a tension of MPa that pulled the pores together (porous dam break, 0.85). 0 =
    #: the cone alone (default: at 0.85 the permeameter's level reads -4.8 % at dt 1 ms against
    #: +2.4 % without; docs/isph.md, "Porous dam break")
    ground_surface_density: Annotated[float, Field(ge=0, le=1)] = 0.0
    #: suction (Pa, positive) that pore water (eps < 1) holds at most: its solved pressure is clamped at
    #: minus this value before the corrector (the ground's air-entry suction: beyond it air enters the
    #: pores, and the model has no capillarity). Off by default (null). At 2 rho_w g H (H the water's
    #: height at the start) the porous dam break at dx 5 mm with dt auto ran to 2 s at cfl 0.2 (it stopped
    #: at 1.09 s without; at cfl 0.15 it stopped at 1.53 s, so not robustly), the free fall at eps0 0.8, dx 1 cm past its stop at 1.11 s, and the permeameter's level
    #: stayed within 1 % of the ODE at dx 5 mm; at rho_w g H the permeameter stalled at dx 5 mm, dt
    #: 0.25 ms (docs/isph.md, "A suction floor on the pore pressure")
    air_entry_suction: Optional[PosFloat] = None
    #: pressure gradient: eq 12 difference form with kernel-gradient correction (default),
    #: plain eq 12, or the symmetric eq 13 form
    gradient: Literal["corrected", "difference", "symmetric"] = "corrected"
    #: with gradient: corrected, whether water inside saturated porous ground of weak drag (eps < 1, no
    #: free-surface particle within its support, implicit drag D = 1 + c (a + b |v|) below 5) takes the
    #: correction too (default: no, the plain eq 12 there). On the sparse, disordered pore water the
    #: correction matrix amplifies the gradient up to 3-5x, more than the pressure equation's Laplacian
    #: assumes, and without drag to damp it the overshoot grew from step to step: the permeameter's plug
    #: pressure alternated (700 / 2000 Pa) and the column bounced off it at dt 0.25 ms (docs/isph.md,
    #: "Surface test in the ground")
    ground_gradient_correction: bool = False
    #: near-contact collision model (MPS family): water particles closer than this fraction of dx
    #: lose their approaching relative velocity (walls: the velocity into the wall); 0 disables.
    #: Acts only on pairs far closer than the lattice spacing; its events are counted per step.
    collision_distance: Annotated[float, Field(ge=0, lt=1)] = 0.8
    #: coefficient of restitution of those collisions
    collision_restitution: Annotated[float, Field(ge=0, le=1)] = 0.2
    #: particle shifting against clustering (Fick's law, Lind et al. 2012 with Skillen et al. 2013's
    #: coefficient): dr = -A h |u| dt grad C, tangential only near the free surface; 0 disables
    shifting: NonNegFloat = 2.0
    #: the shifting's coefficient A for water in porous ground (eps < 1); null: `shifting`. The shift
    #: carries free water across eq 32's ramp into the ground; at A = 2 it set most of the coarse
    #: permeameter's lead over the falling-head ODE and its dependence on dt (docs/isph.md, "A weaker
    #: shift for pore water"). With `shifting` 0 nothing is shifted anywhere.
    ground_shifting: NonNegFloat | None = None
    #: largest shift per step, as a fraction of dx
    shifting_max: Annotated[float, Field(gt=0, le=0.5)] = 0.1
    ppe: PPESolver = PPESolver()
    #: particle motion inside the ground: pore (x moves with vD / eps, the physical reading of
    #: eq 15) or darcy (x moves with vD, the seed's literal reading)
    advection: Literal["pore", "darcy"] = "pore"


def check_ground(cfg) -> None:
    """Soil regions inside the tank, resolvable porosities, markers that resolve the kernel."""
    for k, reg in enumerate(cfg.soil.regions):
        reg.check_in_tank(cfg.dim, cfg.tank.size, f"soil.regions[{k}]")
    check_pore_lattice(cfg)
    if cfg.soil.marker_spacing is not None and cfg.soil.marker_spacing > 2 * cfg.dx:
        fail("soil.marker_spacing", f"must be at most 2 dx = {2 * cfg.dx} (markers must resolve the kernel)")


def check_pore_lattice(cfg) -> None:
    """Water in ground of porosity eps sits on a pore lattice of spacing dx eps^(-1/dim) (eq 33, constant
    particle mass). At or beyond the kernel support (2.4 dx) a particle there has no neighbour: its density
    and PPE row are empty and the first step gives NaN. Such a porosity cannot be resolved at any dx."""
    if cfg.mode != "isph":
        return
    floor = SUPPORT_FACTOR ** (-cfg.dim)
    why = (f"leaves water in the ground on a pore lattice of spacing dx eps^(-1/{cfg.dim}) at or beyond the "
           f"kernel support ({SUPPORT_FACTOR:g} dx), with no neighbours; it must be above {floor:.3f} in {cfg.dim}D")
    for k, reg in enumerate(cfg.soil.regions):
        if reg.eps0 <= floor:
            fail(f"soil.regions[{k}].eps0", f"{reg.eps0:g} {why}")
    for k, block in enumerate(cfg.water):
        if block.porosity <= floor:
            fail(f"water[{k}].porosity", f"{block.porosity:g} {why}")
