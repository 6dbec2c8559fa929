"""Residual and tangent assembly into a 3x3-block ``warp.sparse`` BSR matrix.

The sparsity pattern is built once per mesh (node pairs that share a tet); every Newton
iteration then zeroes the values and lets the element kernel add its blocks in place through a
precomputed element-block to BSR-block map, so the topology is never rebuilt.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse
import warp as wp
import warp.sparse as wps

from warptissue.device import resolve_device
from warptissue.errors import InputError
from warptissue.fem.assembled import Assembly, von_mises
from warptissue.fem.contact import ContactState, RigidContact, RigidContacts
from warptissue.fem.elements import element_geometry
from warptissue.fem.gather import gather_bsr_blocks, gather_vectors
from warptissue.fem.regions import MaterialSlots, material_slots, zero_derivative
from warptissue.fem.sparsity import block_ranges, packed_ranges, sparsity_pattern, tet_problems
from warptissue.fem.support import SupportSprings, SupportSpringSet
from warptissue.fem.viscous import ViscousHistory, elastic_step
from warptissue.kernels import assembly as ka
from warptissue.kernels import sparse as ks
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


@dataclass(frozen=True)
class ElementPart:
    """Some tets of a mesh and their nodes, on the assembler's device
    (:meth:`Assembler.element_part`, :meth:`Assembler.assemble_part`).

    Attributes:
        elements: Tet indices, sorted, (T,) int32 Warp array.
        nodes: The nodes of those tets, sorted, (R,) int64 NumPy array.
        device_nodes: ``nodes`` as an int32 Warp array.
        forces: The part's nodal forces of the last :meth:`Assembler.assemble_part`, (R,)
            vec3d Warp array (its buffer).
        problems: The packed problems its tets belong to, sorted, (q,) int64 (``[0]`` for an
            assembler of one problem).
    """

    elements: wp.array
    nodes: np.ndarray
    device_nodes: wp.array
    forces: wp.array
    problems: np.ndarray


@dataclass(frozen=True)
class _SubmatrixBlocks:
    """The tangent's blocks among some nodes: for block i, its index ``blocks[i]`` in the
    BSR values, its local row ``rows[i]`` and column ``columns[i]`` (positions in ``nodes``),
    on the host and as int32 Warp arrays on the assembler's device."""

    nodes: np.ndarray
    rows: np.ndarray
    blocks: np.ndarray
    columns: np.ndarray
    device_rows: wp.array
    device_blocks: wp.array
    device_columns: wp.array


class Assembler:
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
        self._node_elements: tuple[np.ndarray, np.ndarray] | None = None
        self._part_residual = wp.zeros(mesh.node_count, dtype=wp.vec3d, device=dev)
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
        self._part_scalars = wp.zeros(2 * count, dtype=wp.float64, device=dev)
        self._part_force = wp.zeros(count, dtype=wp.vec3d, device=dev)
        self._tets_host: np.ndarray | None = None
        self._last_submatrix: _SubmatrixBlocks | None = None
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
        wp.launch(
            ka.assemble_elements_kernel,
            dim=self.tet_count,
            inputs=[
                *self._assembly_inputs(u),
                self._block_index,
                self._all_elements,
                int(self.formulation == "mixed"),
                int(with_tangent),
                *self._viscous_inputs(),
            ],
            outputs=[self._residual, self.matrix.values, self._energy, self._min_jacobian],
            device=self.device,
        )
        if self.has_contact:
            self._rigid.force.zero_()
            self._rigid.launch(
                u,
                int(with_tangent),
                self._residual,
                self.matrix.values,
                self._energy,
                self._rigid.force,
            )
        self._springs.launch(u, int(with_tangent), self._residual, self.matrix.values, self._energy)
        matrix = self.matrix if with_tangent else None
        assembly = Assembly(self._residual, matrix, np.nan, np.nan, scalars=self._scalars)
        return assembly.with_scalars(self._scalars.numpy()) if read_scalars else assembly

    def parameter_residual(self, displacement_m: np.ndarray | wp.array, name: str) -> np.ndarray:
        """``dR/d theta``: the internal forces' derivative by one material parameter at fixed u.

        The internal force is linear in every material parameter but the Ogden exponents, so
        for those it is the residual assembled with the parameters' derivative struct
        (:meth:`warptissue.materials.Material.device_params_derivative`, the chain rule from
        the parameter to the device fields included); for ``alpha_i`` it is
        ``ogden_alpha_residual_kernel``.

        Packed problems (K > 1) are differentiated each by its own parameter of that name in
        one launch: the rows of problem k hold ``dR_k / d theta_k`` (the Ogden exponents,
        which need their own kernel, are refused there). A body of several material regions
        is differentiated by one region's parameter (``tumour.C10_Pa``; the default's
        unqualified): the other regions' tets contribute nothing.

        Args:
            displacement_m: Nodal displacements, (N, 3) or a vec3d Warp array, metres.
            name: A parameter of :attr:`material` (``C10_Pa``, ``alpha1``, ``bulk_modulus_Pa``,
                ...; :attr:`warptissue.materials.Material.sensitivity_names`); of every
                problem's material where K > 1.

        Returns:
            dR/d theta, shape (N, 3), N per unit of the parameter (a copy: the assembler's
            residual buffer is reused).
        """
        derivatives, alpha_term = [], -1
        for k, material in enumerate(self.materials):
            alpha_term = material.device_params_derivative(name)[1]  # names a bad one
            if alpha_term >= 0 and (self.problem_count > 1 or len(self._slots.materials) > 1):
                raise InputError(
                    f"problem {k}: the derivative by an Ogden exponent is available for one "
                    "problem of one material per assembler",
                    key="sensitivities",
                    value=name,
                )
        for slot, part in enumerate(self._slots.materials):
            local = self._slots.owner(slot, name)
            derivatives.append(
                zero_derivative(part) if local is None else part.device_params_derivative(local)[0]
            )
        u = self.device_displacement(displacement_m)
        self._residual.zero_()
        viscous = self.viscous
        if alpha_term >= 0:
            wp.launch(
                ka.ogden_alpha_residual_kernel,
                dim=self.tet_count,
                inputs=[*self._element_inputs(u), alpha_term],
                outputs=[self._residual],
                device=self.device,
            )
            explicit = self._residual.numpy().copy()
            if viscous is not None:  # the deviatoric stress of a step is gamma P0 + F Q
                explicit *= viscous.gamma(0)
        else:
            # Linear in the parameters: the residual of the derivative parameters (zero for
            # a Prony parameter), its deviatoric part scaled by each step's gamma.
            self._energy.zero_()
            self._min_jacobian.fill_(np.inf)
            derivative_params = wp.array(derivatives, dtype=MaterialParams, device=self.device)
            wp.launch(
                ka.assemble_elements_kernel,
                dim=self.tet_count,
                inputs=[
                    *self._assembly_inputs(u, problem_params=derivative_params),
                    self._block_index,
                    self._all_elements,
                    int(self.formulation == "mixed"),
                    0,
                    *self._viscous_inputs(zero_history=True),
                ],
                outputs=[self._residual, self.matrix.values, self._energy, self._min_jacobian],
                device=self.device,
            )
            explicit = self._residual.numpy().copy()
        count = self.problem_count  # a problem's contact scales with entry k's modulus
        d_shears = np.array([float(derivative.shear_modulus) for derivative in derivatives[:count]])
        moduli = np.array([material.initial_shear_modulus_Pa for material in self.materials])
        explicit = explicit + self._rigid.parameter_residual(
            u, self.matrix.values, d_shears, moduli
        )
        if viscous is None or name not in viscous.names:
            return explicit
        self._residual.zero_()
        viscous.history_residual(self, u, name, self._residual)
        return explicit + self._residual.numpy()

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

    def node_patch(self, nodes: np.ndarray) -> np.ndarray:
        """The given nodes and every node sharing a tet with one of them.

        Args:
            nodes: Node indices, (k,).

        Returns:
            Sorted unique node indices, (P,) int64.

        Raises:
            InputError: A node index is out of range.
        """
        nodes = self._node_indices(nodes)
        neighbours = self._pattern_columns[block_ranges(self._pattern_offsets, nodes)]
        return np.union1d(nodes, neighbours)

    def element_part(
        self, *, nodes: np.ndarray | None = None, elements: np.ndarray | None = None
    ) -> ElementPart:
        """A part of the mesh for :meth:`assemble_part`: the tets that hold at least one of
        ``nodes``, or the tets ``elements``; with their nodes.

        Args:
            nodes: Node indices, (k,).
            elements: Tet indices, (T,) (instead of ``nodes``).

        Returns:
            An :class:`ElementPart`.

        Raises:
            InputError: Neither or both given, or an index out of range.
        """
        if (nodes is None) == (elements is None):
            raise InputError("give the part's nodes or its elements, not both")
        if elements is None:
            nodes = self._node_indices(nodes)
            if self._node_elements is None:  # node -> tets, built once
                tets = self._tets.numpy()
                owners = np.repeat(np.arange(self.tet_count, dtype=np.int32), tets.shape[1])
                order = np.argsort(tets.reshape(-1), kind="stable")
                offsets = np.zeros(self.node_count + 1, dtype=np.int64)
                np.cumsum(np.bincount(tets.reshape(-1), minlength=self.node_count), out=offsets[1:])
                self._node_elements = (offsets, owners[order])
            offsets, owners = self._node_elements
            elements = np.unique(owners[block_ranges(offsets, nodes)])
        else:
            elements = np.unique(np.asarray(elements, dtype=np.int64).reshape(-1))
            if elements.size and (elements[0] < 0 or elements[-1] >= self.tet_count):
                raise InputError(
                    f"element indices must lie in [0, {self.tet_count})", key="elements"
                )
        if self._tets_host is None:
            self._tets_host = self._tets.numpy()
        part_nodes = np.unique(self._tets_host[elements])
        return ElementPart(
            elements=wp.array(elements.astype(np.int32), dtype=wp.int32, device=self.device),
            nodes=part_nodes.astype(np.int64),
            device_nodes=wp.array(part_nodes.astype(np.int32), dtype=wp.int32, device=self.device),
            forces=wp.zeros(len(part_nodes), dtype=wp.vec3d, device=self.device),
            problems=np.unique(self._element_problem_host[elements]).astype(np.int64),
        )

    def assemble_part(
        self,
        displacement_m: np.ndarray | wp.array,
        part: ElementPart,
        *,
        with_tangent: bool = False,
    ) -> tuple[np.ndarray, float, float]:
        """The internal forces and energy of some tets alone (and of the rigid contact).

        For a local solve on a patch of nodes (the nonlinear elimination): where only the
        patch's nodes move, only the tets that hold them change their forces and energy, so
        the whole residual follows from the last one plus the change of this part, at the
        part's nodes. The rigid contacts, where there are any, are evaluated at every
        candidate node (its unchanged nodes cancel in that difference; the forces returned
        hold their share at the part's nodes).

        Args:
            displacement_m: Nodal displacements, (N, 3), m (NumPy or a vec3d Warp array).
            part: The tets and their nodes (:meth:`element_part`).
            with_tangent: Also assemble their tangent: every block that these tets add to is
                zeroed first, so a block of two nodes whose tets all lie in the part (two
                nodes of the patch the part was made for) is exact afterwards, and the
                others are not: the assembler's matrix must be assembled again
                (:meth:`assemble`) before it is used as a whole.

        Returns:
            (forces of these tets and of the contact at ``part.nodes``, (R, 3), N; their
            energy with the contact's at every candidate node of their problems
            (``part.problems``), J; the smallest det F over their quadrature points).
        """
        u = self.device_displacement(displacement_m)
        self._part_residual.zero_()
        scalars = self._part_scalars
        scalars.zero_()
        count = self.problem_count
        energy, min_jacobian = scalars[:count], scalars[count:]
        min_jacobian.fill_(np.inf)
        if with_tangent:
            wp.launch(
                ka.zero_element_blocks_kernel,
                dim=(part.elements.shape[0], self.nodes_per_tet**2),
                inputs=[part.elements, self._block_index],
                outputs=[self.matrix.values],
                device=self.device,
            )
        wp.launch(
            ka.assemble_elements_kernel,
            dim=part.elements.shape[0],
            inputs=[
                *self._assembly_inputs(u),
                self._block_index,
                part.elements,
                int(self.formulation == "mixed"),
                int(with_tangent),
                *self._viscous_inputs(),
            ],
            outputs=[self._part_residual, self.matrix.values, energy, min_jacobian],
            device=self.device,
        )
        if self.has_contact:
            self._rigid.launch(
                u,
                int(with_tangent),
                self._part_residual,
                self.matrix.values,
                energy,
                self._part_force,
            )
        self._springs.launch(u, int(with_tangent), self._part_residual, self.matrix.values, energy)
        gather_vectors(self._part_residual, part.device_nodes, part.forces)
        values = scalars.numpy()
        return (
            part.forces.numpy().copy(),
            float(values[:count][part.problems].sum()),
            float(values[count:].min()),
        )

    def set_residual(self, residual_N: Any) -> wp.array:
        """Overwrite the assembler's residual buffer (the one :meth:`assemble` returns), e.g.
        with a residual updated from a part (:meth:`assemble_part`).

        Args:
            residual_N: (N, 3), N: NumPy, or an array on the assembler's CUDA device (CuPy;
                copied on the device).

        Returns:
            The buffer, a vec3d Warp array (N,).
        """
        self._residual.assign(self._vec3_array(residual_N, "residual"))
        return self._residual

    def _submatrix_blocks(self, nodes: np.ndarray) -> _SubmatrixBlocks:
        """The tangent's blocks among ``nodes`` (sorted and unique, checked); the last
        patch's are kept, since the nonlinear elimination asks for the same patch at each
        of its local iterations."""
        nodes = self._node_indices(nodes)
        last = self._last_submatrix
        if last is not None and np.array_equal(last.nodes, nodes):
            return last
        if np.any(np.diff(nodes) <= 0):
            raise InputError("nodes must be sorted and unique", value=nodes.tolist()[:20])
        local = np.full(self.node_count, -1, dtype=np.int64)
        local[nodes] = np.arange(len(nodes))
        counts = self._pattern_offsets[nodes + 1] - self._pattern_offsets[nodes]
        rows = np.repeat(np.arange(len(nodes)), counts)
        blocks = block_ranges(self._pattern_offsets, nodes)
        columns = local[self._pattern_columns[blocks]]
        inside = columns >= 0
        rows, blocks, columns = rows[inside], blocks[inside], columns[inside]

        def device(values: np.ndarray) -> wp.array:
            return wp.array(values.astype(np.int32), dtype=wp.int32, device=self.device)

        self._last_submatrix = _SubmatrixBlocks(
            nodes=nodes.copy(),
            rows=rows,
            blocks=blocks,
            columns=columns,
            device_rows=device(rows),
            device_blocks=device(blocks),
            device_columns=device(columns),
        )
        return self._last_submatrix

    def tangent_submatrix_dense(self, nodes: np.ndarray) -> wp.array:
        """The last assembled tangent restricted to ``nodes``, as a dense matrix on the
        assembler's device (for a small patch's solve there, without a copy to the host).

        Args:
            nodes: Sorted unique node indices, (P,).

        Returns:
            float64 Warp array (3P, 3P), N/m; dof ``3 i + c`` is component c of ``nodes[i]``.

        Raises:
            InputError: A node index is out of range, or the indices are not sorted and unique.
        """
        part = self._submatrix_blocks(nodes)
        size = 3 * len(part.nodes)
        dense = wp.zeros((size, size), dtype=wp.float64, device=self.device)
        if len(part.blocks):
            wp.launch(
                ks.blocks_to_dense_kernel,
                dim=len(part.blocks),
                inputs=[
                    self.matrix.values,
                    part.device_blocks,
                    part.device_rows,
                    part.device_columns,
                ],
                outputs=[dense],
                device=self.device,
            )
        return dense

    def tangent_submatrix(self, nodes: np.ndarray) -> scipy.sparse.csr_matrix:
        """The last assembled tangent restricted to the rows and columns of ``nodes``.

        Only the needed blocks leave the device.

        Args:
            nodes: Sorted unique node indices, (P,).

        Returns:
            Scalar CSR matrix (3P, 3P), N/m; dof ``3 i + c`` is component c of ``nodes[i]``.

        Raises:
            InputError: A node index is out of range, or the indices are not sorted and unique.
        """
        part = self._submatrix_blocks(nodes)
        rows, columns, size = part.rows, part.columns, 3 * len(part.nodes)
        gathered = wp.empty(len(part.blocks), dtype=wp.mat33d, device=self.device)
        gather_bsr_blocks(self.matrix, part.device_blocks, gathered)
        component = np.arange(3)
        row_dofs = 3 * rows[:, None, None] + component[None, :, None]
        column_dofs = 3 * columns[:, None, None] + component[None, None, :]
        shape = (len(part.blocks), 3, 3)
        return scipy.sparse.csr_matrix(
            (
                gathered.numpy().reshape(-1),
                (
                    np.broadcast_to(row_dofs, shape).reshape(-1),
                    np.broadcast_to(column_dofs, shape).reshape(-1),
                ),
            ),
            shape=(size, size),
        )

    def _node_indices(self, nodes: np.ndarray) -> np.ndarray:
        nodes = np.asarray(nodes, dtype=np.int64).reshape(-1)
        outside = (nodes < 0) | (nodes >= self.node_count)
        if np.any(outside):
            raise InputError(
                f"node indices must lie in [0, {self.node_count})",
                value=nodes[outside][:20].tolist(),
            )
        return nodes

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
