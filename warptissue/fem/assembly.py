"""Residual and tangent assembly into a 3x3-block ``warp.sparse`` BSR matrix.

The sparsity pattern is built once per mesh (node pairs that share a tet); every Newton
iteration then zeroes the values and lets the element kernel add its blocks in place through a
precomputed element-block to BSR-block map, so the topology is never rebuilt.

:class:`Assembler` holds the mesh, the materials, the contacts and the springs, and assembles
the whole residual and tangent; its parts in other modules add the assembly on patches of
nodes for the nonlinear elimination (:mod:`warptissue.fem.patches`) and the residual's
derivatives by the material parameters (:mod:`warptissue.fem.parameter_residual`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import warp as wp
import warp.sparse as wps

from warptissue._deprecated import moved_names
from warptissue.device import resolve_device
from warptissue.errors import InputError
from warptissue.fem.assembled import Assembly, von_mises
from warptissue.fem.contact import ContactState, RigidContact, RigidContacts
from warptissue.fem.elements import element_geometry
from warptissue.fem.parameter_residual import ParameterResidual
from warptissue.fem.patches import ElementPart, PatchAssembly
from warptissue.fem.regions import MaterialSlots, material_slots
from warptissue.fem.sparsity import packed_ranges, sparsity_pattern, tet_problems
from warptissue.fem.support import SupportSprings, SupportSpringSet
from warptissue.fem.viscous import ViscousHistory, elastic_step
from warptissue.kernels import assembly as ka
from warptissue.kernels.materials import MaterialParams
from warptissue.materials import Material, MaterialRegions, Viscoelastic
from warptissue.mesh import TetMesh

__all__ = [
    "FORMULATIONS",
    "Assembler",
    "Assembly",
    "ElementPart",
    "von_mises",
]

FORMULATIONS = ("mixed", "displacement")
"""``mixed``: TET10 with element mean dilatation (P2/P0); ``displacement``: pure displacement."""


class Assembler(PatchAssembly, ParameterResidual):
    """Assembles internal forces and the consistent tangent of a tet mesh on a Warp device.

    Args:
        mesh: TET4 or TET10 mesh (metres).
        material: Any :mod:`warptissue.materials` material; or, for K independent problems
            packed into one mesh (:func:`warptissue.fem.packing.pack_meshes`), one elastic
            material per problem. A :class:`warptissue.materials.MaterialRegions` gives the
            tets of each of its named regions (by :attr:`warptissue.mesh.TetMesh.tet_regions`)
            that region's material.
        formulation: ``"mixed"`` (TET10 only: element mean dilatation, locking free) or
            ``"displacement"``.
        device: Warp device; None for Warp's default.
        element_problem: The problem of each tet, (tet_count,), integers in [0, K) (None:
            all 0, one problem). With K problems each assembly launch covers all of them;
            energies and smallest J come per problem as well
            (:attr:`Assembly.problem_energies_J`).

    Attributes:
        node_count, tet_count, device, formulation.
        material: The material (None where K > 1).
        materials: One material per problem, (K,).
        problem_count: K.
        tet_volumes: Reference element volumes, shape (tet_count,), m^3.
    """

    def __init__(
        self,
        mesh: TetMesh,
        material: Material | Sequence[Material],
        *,
        formulation: str = "mixed",
        device: str | None = None,
        element_problem: np.ndarray | None = None,
    ) -> None:
        if formulation not in FORMULATIONS:
            raise InputError(
                f"formulation must be one of {FORMULATIONS}",
                key="formulation",
                value=formulation,
            )
        if formulation == "mixed" and mesh.nodes_per_tet != 10:
            raise InputError(
                "the mixed (mean-dilatation) formulation needs TET10 elements: with TET4 a "
                "constant pressure per element locks; promote the mesh with "
                "warptissue.mesh.to_tet10 or use formulation='displacement'",
                key="formulation",
                value=formulation,
            )
        if mesh.tet_count == 0:
            raise InputError("the mesh has no elements")
        self.device = resolve_device(device)
        self.formulation = formulation
        self.node_count = mesh.node_count
        self.tet_count = mesh.tet_count
        self.nodes_per_tet = mesh.nodes_per_tet
        geometry = element_geometry(mesh)
        self.tet_volumes = geometry.tet_volumes
        dev = self.device
        self._tets = wp.array(mesh.tets, dtype=wp.int32, device=dev)
        self._shape_gradients = wp.array(geometry.shape_gradients, dtype=wp.vec3d, device=dev)
        self._quadrature_volumes = wp.array(
            geometry.quadrature_volumes, dtype=wp.float64, device=dev
        )
        self.problem_count = 1 if isinstance(material, Material) else len(material)
        problems = tet_problems(element_problem, mesh.tet_count, self.problem_count)
        self._build_pattern(mesh.tets, problems)
        self._all_elements = wp.array(
            np.arange(self.tet_count, dtype=np.int32), dtype=wp.int32, device=dev
        )
        self._element_problem = wp.array(problems, dtype=wp.int32, device=dev)
        self._tet_regions_host = mesh.tet_regions
        count = self.problem_count
        node_problem = np.zeros(self.node_count, dtype=np.int32)
        node_problem[mesh.tets] = problems[:, None]
        self._node_problem = wp.array(node_problem, dtype=wp.int32, device=dev)
        self._node_problem_host = node_problem
        self._element_problem_host = problems
        # First node of each problem and the node count at the end, where the problems are
        # packed (pack_meshes; None where not): a contact's nodes are in its problem's own
        # numbering (set_contact).
        self._node_offsets: np.ndarray | None = np.array([0, self.node_count], dtype=np.int64)
        if count > 1:
            ranges = packed_ranges(mesh.tets, self.node_count, problems)
            self._node_offsets = (
                None
                if ranges is None
                else np.array([r[2] for r in ranges] + [self.node_count], dtype=np.int64)
            )
        # The damping of each problem's tangent (eliminate), copied only when it changes.
        self._damping_host = np.zeros(count)
        self._damping = wp.zeros(count, dtype=wp.float64, device=dev)
        # Energy and smallest J per problem, in one array so that one copy reads both.
        self._scalars = wp.zeros(2 * count, dtype=wp.float64, device=dev)
        self._energy, self._min_jacobian = self._scalars[:count], self._scalars[count:]
        self._init_patches()
        self._rigid = RigidContacts(
            points=wp.array(mesh.points, dtype=wp.vec3d, device=dev),
            pattern=(self._pattern_offsets, self._pattern_columns),
            node_offsets=self._node_offsets,
            node_problem=node_problem,
            problem_count=count,
            device=dev,
        )
        self._springs = SupportSpringSet(
            pattern_offsets=self._pattern_offsets,
            pattern_columns=self._pattern_columns,
            node_offsets=self._node_offsets,
            problem_count=count,
            device=dev,
        )
        self._residual = wp.zeros(self.node_count, dtype=wp.vec3d, device=dev)
        self._displacement = wp.zeros(self.node_count, dtype=wp.vec3d, device=dev)
        self._no_history = wp.zeros((1, 1), dtype=wp.mat33d, device=dev)
        # Every problem's step of an elastic material (inactive), one per problem.
        self._elastic_steps = wp.array(
            [elastic_step()] * self.problem_count, dtype=ka.ViscousStep, device=dev
        )
        self.viscous: ViscousHistory | None = None
        self._zero_history: wp.array | None = None
        self.set_material(material)

    def set_material(self, material: Material | Sequence[Material]) -> None:
        """Use new material parameters from the next assembly on (same mesh and pattern).

        Where a material is :class:`warptissue.materials.Viscoelastic`, the problems get a
        :class:`warptissue.fem.viscous.ViscousHistory` (:attr:`viscous`) at the undeformed,
        unloaded state; otherwise :attr:`viscous` is None. An assembler of K packed problems
        takes a sequence of K materials.
        """
        materials = (material,) if isinstance(material, Material) else tuple(material)
        if len(materials) != self.problem_count:
            raise InputError(
                f"one material per packed problem: {self.problem_count} expected",
                key="material",
                value=len(materials),
            )
        for each in materials:
            if not isinstance(each, Material):
                raise InputError("material must be a warptissue.materials material", value=each)
        regions = any(isinstance(each, MaterialRegions) for each in materials)
        if regions and any(isinstance(each, Viscoelastic) for each in materials):
            raise InputError(
                "packed problems with material regions are elastic: a viscoelastic problem "
                "goes in an assembler of its own",
                key="material",
            )
        self.materials = materials
        self._slots: MaterialSlots = material_slots(
            materials, self._element_problem_host, self._tet_regions_host
        )
        # Entry k is problem k's material (the viscous kernels read it by problem), then the
        # named regions' (warptissue.fem.regions).
        self._problem_params = wp.array(
            [each.device_params() for each in self._slots.materials],
            dtype=MaterialParams,
            device=self.device,
        )
        self._element_material = wp.array(
            self._slots.element_material, dtype=wp.int32, device=self.device
        )
        if any(isinstance(each, Viscoelastic) for each in materials):
            counts = tuple(
                each.term_count if isinstance(each, Viscoelastic) else 0 for each in materials
            )
            if self.viscous is not None and self.viscous.term_counts() == counts:
                self.viscous.reset(materials)
            else:
                self.viscous = ViscousHistory(
                    materials,
                    element_problem=self._element_problem.numpy(),
                    tet_count=self.tet_count,
                    quadrature_points=self._quadrature_volumes.shape[1],
                    device=self.device,
                )
        else:
            self.viscous = None
        self.material = materials[0] if self.problem_count == 1 else None
        self._params = self._slots.materials[0].device_params()

    def set_contact(self, contact: RigidContact | Sequence[RigidContact | None] | None) -> None:
        """Press rigid indenters into the bodies from the next assembly on (None: no contact).

        Every later :meth:`assemble` adds the frictionless penalty of each contact at its
        current depth (:mod:`warptissue.fem.contact`) to the residual (``R = f_int - f_c``),
        the tangent's diagonal blocks and its problem's energy; :meth:`set_load` moves the
        indenters. All problems' candidate nodes are evaluated in one launch, each with its
        own problem's body and penalty stiffness.

        Args:
            contact: For one problem, its :class:`warptissue.fem.contact.RigidContact` or
                None. For K packed problems (:func:`warptissue.fem.packing.pack_meshes`), a
                sequence of K entries, each a contact whose nodes are in its own problem's
                numbering, or None (a problem without one, e.g. a sharp flat punch); None
                alone: no contact anywhere.

        Raises:
            InputError: Not one entry per problem, a contact node outside its problem, or
                contacts on problems that are not packed in contiguous node ranges.
        """
        self._rigid.set(contact)

    @property
    def has_contact(self) -> bool:
        """Whether any problem has a rigid contact."""
        return self._rigid.has_contact

    def set_springs(self, springs: SupportSprings | Sequence[SupportSprings | None] | None) -> None:
        """Hold nodes by linear springs to the ground from the next assembly on (an elastic
        foundation, :mod:`warptissue.fem.support`; None: none).

        Every later :meth:`assemble` adds ``S u`` to the residual, ``S`` to the tangent's
        diagonal blocks and ``u . S u / 2`` to its problem's energy.

        Args:
            springs: For one problem, its :class:`warptissue.fem.support.SupportSprings` or
                None; for K packed problems, K entries in their own problems' numbering.

        Raises:
            InputError: Not one entry per problem, or a node outside its problem.
        """
        self._springs.set(springs)

    @property
    def has_springs(self) -> bool:
        """Whether any problem is held by support springs."""
        return self._springs.has_springs

    def spring_product(self, values: np.ndarray) -> np.ndarray:
        """``S x``: the support springs' stiffness times nodal vectors ``values`` (N, 3), (N, 3)
        (zero where no spring holds a node)."""
        return self._springs.product(values)

    @property
    def contact(self) -> RigidContact | None:
        """The rigid contact of an assembler of one problem (None without one, and always
        None where K > 1: see :attr:`contacts`)."""
        return self._rigid.contact

    @property
    def contacts(self) -> tuple[RigidContact | None, ...]:
        """Each problem's rigid contact or None, (K,) (:meth:`set_contact`)."""
        return self._rigid.contacts

    def set_load(self, load: Any) -> None:
        """The load of the next assemblies: each rigid indenter's depth, m (no-op without one).

        :func:`warptissue.fem.solve_quasistatic` calls it before each load increment.

        Args:
            load: The depth, m: a number for one problem; for K packed problems one per
                problem, (K,) (a number: the same for all).

        Raises:
            InputError: Not one depth per problem.
        """
        self._rigid.set_load(load)

    def contact_state(
        self, displacement_m: np.ndarray | wp.array, *, problem: int | None = None
    ) -> ContactState:
        """The rigid contact at a displacement and the current depth: each candidate node's gap
        and contact force (:class:`warptissue.fem.contact.ContactState`). Leaves the
        assembler's residual, tangent and energy as they were.

        Args:
            displacement_m: Nodal displacements, (N, 3), m (NumPy or a vec3d Warp array).
            problem: Of K packed problems, whose contact (its nodes in its own numbering);
                needed where K > 1 (:meth:`contact_states` gives all of them at once).

        Raises:
            InputError: No rigid contact is set (on that problem), or no ``problem`` where
                K > 1.
        """
        if problem is None:
            if self.problem_count > 1:
                raise InputError(
                    f"the assembler packs {self.problem_count} problems: name the problem "
                    "(or use contact_states)",
                    key="problem",
                )
            problem = 0
        if not 0 <= problem < self.problem_count:
            raise InputError(
                f"problem must lie in [0, {self.problem_count})", key="problem", value=problem
            )
        if self.contacts[problem] is None:
            raise InputError("no rigid contact is set (a sharp flat punch has none)", key="kind")
        return self.contact_states(displacement_m)[problem]

    def contact_states(self, displacement_m: np.ndarray | wp.array) -> list[ContactState | None]:
        """Every problem's :meth:`contact_state` from one launch: one entry per packed problem,
        None where it has no rigid contact; each state's nodes in its problem's own numbering.

        Args:
            displacement_m: Nodal displacements of all problems, (N, 3), m; each problem's
                depth is the last :meth:`set_load`'s.
        """
        return self._rigid.states(self.device_displacement(displacement_m), self.matrix.values)

    def reset_history(self) -> None:
        """Back to the unloaded state at t = 0 (a viscoelastic material forgets its history)."""
        if self.viscous is not None:
            self.viscous.reset()

    def _viscous_inputs(self, *, zero_history: bool = False) -> list[Any]:
        """The ``viscous, frozen`` inputs of the element kernels for the current step."""
        if self.viscous is None:
            return [self._elastic_steps, self._no_history]
        if zero_history:
            if self._zero_history is None or self._zero_history.shape != self.viscous.frozen.shape:
                self._zero_history = wp.zeros_like(self.viscous.frozen)
            return [self.viscous.steps, self._zero_history]
        return [self.viscous.steps, self.viscous.frozen]

    def _build_pattern(self, tets: np.ndarray, problems: np.ndarray) -> None:
        n = self.node_count
        block_rows, block_cols, block_index = sparsity_pattern(tets, n, problems)
        self._block_index_host = block_index
        self._block_index = wp.array(self._block_index_host, dtype=wp.int32, device=self.device)
        self.matrix = wps.bsr_zeros(n, n, block_type=wp.mat33d, device=self.device)
        wps.bsr_set_from_triplets(
            self.matrix,
            wp.array(block_rows, dtype=wp.int32, device=self.device),
            wp.array(block_cols, dtype=wp.int32, device=self.device),
            wp.zeros(len(block_rows), dtype=wp.mat33d, device=self.device),
            prune_numerical_zeros=False,
        )
        offsets = np.concatenate([[0], np.cumsum(np.bincount(block_rows, minlength=n))])
        self._pattern_offsets = offsets
        self._pattern_columns = block_cols
        diagonal = np.flatnonzero(np.repeat(np.arange(n), np.diff(offsets)) == block_cols)
        if len(diagonal) != n:
            raise InputError("every node must belong to an element", key="mesh")
        self._diagonal_blocks = diagonal.astype(np.int32)
        nnz = len(block_rows)
        if not (
            np.array_equal(self.matrix.offsets.numpy()[: n + 1], offsets)
            and np.array_equal(self.matrix.columns.numpy()[:nnz], block_cols)
        ):
            raise RuntimeError("warp.sparse reordered the sparsity pattern unexpectedly")
        self.block_count = nnz

    def assemble(
        self,
        displacement_m: np.ndarray | wp.array,
        *,
        with_tangent: bool = True,
        read_scalars: bool = True,
    ) -> Assembly:
        """Internal forces, tangent and energy at a nodal displacement.

        Args:
            displacement_m: Nodal displacements, shape (N, 3) (NumPy or a vec3d Warp array on
                the assembler's device), metres.
            with_tangent: Also assemble the tangent matrix.
            read_scalars: Read the energies and smallest det F now (False: the caller reads
                :attr:`Assembly.scalars` itself, on a GPU with other values in one copy).

        Returns:
            An :class:`Assembly`; its arrays live on the assembler's device and are reused by
            the next call.
        """
        u = self.device_displacement(displacement_m)
        self._residual.zero_()
        self._energy.zero_()
        self._min_jacobian.fill_(np.inf)
        if with_tangent:
            self.matrix.values.zero_()
        if self.has_contact:
            self._rigid.force.zero_()
        self._launch_elements(
            u,
            self._all_elements,
            with_tangent=with_tangent,
            residual=self._residual,
            energy=self._energy,
            min_jacobian=self._min_jacobian,
            contact_force=self._rigid.force,
        )
        matrix = self.matrix if with_tangent else None
        assembly = Assembly(self._residual, matrix, np.nan, np.nan, scalars=self._scalars)
        return assembly.with_scalars(self._scalars.numpy()) if read_scalars else assembly

    def _launch_elements(
        self,
        u: wp.array,
        elements: wp.array,
        *,
        with_tangent: bool,
        residual: wp.array,
        energy: wp.array,
        min_jacobian: wp.array,
        contact_force: wp.array,
    ) -> None:
        """Add the internal forces (and tangent blocks) of ``elements``, then those of the
        rigid contacts and the support springs, into ``residual``, the matrix's values,
        ``energy`` and ``min_jacobian`` (per problem); the contacts' force into
        ``contact_force``."""
        wp.launch(
            ka.assemble_elements_kernel,
            dim=elements.shape[0],
            inputs=[
                *self._assembly_inputs(u),
                self._block_index,
                elements,
                int(self.formulation == "mixed"),
                int(with_tangent),
                *self._viscous_inputs(),
            ],
            outputs=[residual, self.matrix.values, energy, min_jacobian],
            device=self.device,
        )
        if self.has_contact:
            self._rigid.launch(
                u, int(with_tangent), residual, self.matrix.values, energy, contact_force
            )
        self._springs.launch(u, int(with_tangent), residual, self.matrix.values, energy)

    def eliminate(self, constrained: wp.array, *, damping: Any = 0.0) -> None:
        """Zero the rows and columns of constrained dofs in ``self.matrix``, 1 on the diagonal,
        in place; optionally damp the free dofs' diagonal.

        Args:
            constrained: Warp vec3d array (N,), 1.0 where a component is prescribed.
            damping: Levenberg-Marquardt factor lambda >= 0, one for all problems or one per
                packed problem, (K,): each free diagonal entry K_ii of a problem becomes
                ``K_ii + lambda |K_ii|`` (0: the tangent unchanged).

        Raises:
            InputError: A negative or non-finite ``damping``, or not one per problem.
        """
        factors = np.asarray(damping, dtype=np.float64)
        if factors.ndim == 0:
            factors = np.full(self.problem_count, float(factors))
        if factors.shape != (self.problem_count,) or not (
            np.all(np.isfinite(factors)) and np.all(factors >= 0.0)
        ):
            raise InputError("damping must be finite and >= 0, one per problem", value=damping)
        if not np.array_equal(factors, self._damping_host):
            self._damping_host = factors.copy()
            self._damping.assign(self._damping_host)
        wp.launch(
            ka.eliminate_dirichlet_kernel,
            dim=self.node_count,
            inputs=[
                self.matrix.offsets,
                self.matrix.columns,
                constrained,
                self._node_problem,
                self._damping,
            ],
            outputs=[self.matrix.values],
            device=self.device,
        )

    def cauchy_stress(self, displacement_m: np.ndarray | wp.array) -> np.ndarray:
        """Volume-averaged Cauchy stress per tet (xx, yy, zz, yz, xz, xy), shape (M, 6), Pa.

        A viscoelastic material gives the stress of its last committed step; packed problems
        each their own material's.
        """
        u = self.device_displacement(displacement_m)
        stress = wp.zeros((self.tet_count, 6), dtype=wp.float64, device=self.device)
        wp.launch(
            ka.cauchy_stress_kernel,
            dim=self.tet_count,
            inputs=[
                *self._assembly_inputs(u),
                int(self.formulation == "mixed"),
                *(
                    self._viscous_inputs()
                    if self.viscous is None
                    else list(self.viscous.stress_state())
                ),
            ],
            outputs=[stress],
            device=self.device,
        )
        return stress.numpy()

    def _assembly_inputs(
        self, displacement: wp.array, *, problem_params: wp.array | None = None
    ) -> list[Any]:
        """The leading inputs of ``assemble_elements_kernel`` and ``cauchy_stress_kernel``:
        ``[material_params, element_problem, element_material, tets, shape_gradients,
        quadrature_volumes, displacement]`` (``problem_params``: the materials' table,
        :mod:`warptissue.fem.regions`, by default)."""
        return [
            self._problem_params if problem_params is None else problem_params,
            self._element_problem,
            self._element_material,
            *self._element_inputs(displacement)[1:],
        ]

    def _element_inputs(self, displacement: wp.array) -> list[Any]:
        """The leading inputs of the element kernels of ``kernels/assembly.py`` that take one
        material (``ogden_alpha_residual_kernel``; the others take one per problem,
        :meth:`_assembly_inputs`).

        Args:
            displacement: Nodal displacements on the assembler's device, vec3d (N,), metres.

        Returns:
            ``[params, tets, shape_gradients, quadrature_volumes, displacement]``, in the order
            of the kernels' first five arguments.
        """
        return [
            self._params,
            self._tets,
            self._shape_gradients,
            self._quadrature_volumes,
            displacement,
        ]

    def device_displacement(self, displacement_m: Any) -> wp.array:
        """The displacement as a vec3d Warp array on the assembler's device: a Warp array as
        it is; NumPy (N, 3), or a CuPy (N, 3) array on the assembler's CUDA device, is copied
        into the assembler's own buffer (reused by the next call; a device-to-device copy for
        CuPy)."""
        if isinstance(displacement_m, wp.array):
            if displacement_m.shape != (self.node_count,) or displacement_m.dtype != wp.vec3d:
                raise InputError("displacement must be a vec3d array of one entry per node")
            return displacement_m
        self._displacement.assign(self._vec3_array(displacement_m, "displacement"))
        return self._displacement

    def _vec3_array(self, values: Any, name: str) -> np.ndarray | wp.array:
        """An (N, 3) float64 array as NumPy or, for a CUDA array (``__cuda_array_interface__``,
        e.g. CuPy) on this assembler's device, as a Warp view of it; the shape is checked."""
        if self.device.is_cuda and hasattr(values, "__cuda_array_interface__"):
            if tuple(values.shape) != (self.node_count, 3) or values.dtype != np.float64:
                raise InputError(
                    f"{name} must be float64 of shape ({self.node_count}, 3)",
                    value=(tuple(values.shape), str(values.dtype)),
                )
            return wp.array(values, dtype=wp.vec3d, device=self.device)
        array = np.ascontiguousarray(values, dtype=np.float64)
        if array.shape != (self.node_count, 3):
            raise InputError(f"{name} must have shape ({self.node_count}, 3)", value=array.shape)
        return array


# The old paths of names that moved, with a DeprecationWarning naming the new one
# (warptissue._deprecated.MOVED).
__getattr__ = moved_names(__name__)
