"""Frictionless penalty contact of rigid indenters (float64), launched by
:mod:`warptissue.fem.contact` through :class:`warptissue.fem.assembly.Assembler`: the signed
distance of a point to a rigid body and the contact's residual and tangent blocks.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

# The kernels below are compiled in the Warp module of assembly.py: the FE's kernels are one
# Warp module, so that a cold start compiles the constitutive code once
# (docs/design-notes/kernel-modules.md; __init__.py imports every file of that module).
FE_MODULE = wp.get_module("warptissue.kernels.assembly")

RIGID_SPHERE = wp.constant(0)
RIGID_PLATE = wp.constant(1)
RIGID_PUNCH = wp.constant(2)
RIGID_WEDGE = wp.constant(3)


@wp.struct
class RigidBody:
    """A rigid indenter at its current position (SI units), described in its own frame.

    ``axes``: the frame's unit axes as rows (world coordinates), so that a world point ``x``
    has the frame coordinates ``axes x``; every other field and the shapes below are in frame
    coordinates (the identity: the world's, the probe along -z).

    ``kind``: ``RIGID_SPHERE`` (centre ``point``, radius ``radius``), ``RIGID_PLATE`` (the
    plane ``z = point[2]``, filling the half-space above), ``RIGID_PUNCH`` (a flat-ended
    cylinder along z of radius ``radius`` whose end face lies at ``z = point[2]`` on the axis
    through ``point``, its edge rounded with radius ``edge_radius``) or ``RIGID_WEDGE`` (a
    wedge along y whose rounded tip, radius ``edge_radius``, has its lowest line through
    ``point``, flanks at ``half_angle`` (rad) from the vertical).
    """

    kind: int
    axes: wp.mat33d
    point: wp.vec3d
    radius: wp.float64
    edge_radius: wp.float64
    half_angle: wp.float64


@wp.struct
class RigidContactPoint:
    """Signed distance ``gap`` (m, negative inside the body) of a point to a rigid body, the
    body's outward unit normal ``normal`` at the closest point, and ``normal_gradient`` =
    d normal / d x (1/m), symmetric, used by the consistent tangent."""

    gap: wp.float64
    normal: wp.vec3d
    normal_gradient: wp.mat33d


@wp.func
def distance_to_point(offset: wp.vec3d, plane_only: int) -> RigidContactPoint:
    """The distance to a point (``offset = x - p``) and its normal gradient ``(I - n n^T)/d``;
    ``plane_only`` restricts both to the x-z plane (the distance to a line along y)."""
    result = RigidContactPoint()
    d = wp.length(offset)
    result.gap = d
    eye = wp.identity(n=3, dtype=wp.float64)
    if plane_only != 0:
        eye = wp.mat33d(
            wp.float64(1.0), wp.float64(0.0), wp.float64(0.0),
            wp.float64(0.0), wp.float64(0.0), wp.float64(0.0),
            wp.float64(0.0), wp.float64(0.0), wp.float64(1.0),
        )  # fmt: skip
    if d > wp.float64(0.0):
        n = offset / d
        result.normal = n
        result.normal_gradient = (eye - wp.outer(n, n)) / d
    else:
        result.normal = wp.vec3d(wp.float64(0.0), wp.float64(0.0), wp.float64(-1.0))
    return result


@wp.func
def rigid_contact_point(body: RigidBody, x: wp.vec3d) -> RigidContactPoint:
    """Signed distance, normal and normal gradient of the point ``x`` (frame coordinates,
    ``RigidBody``) to ``body``, in frame coordinates.

    The punch is the Minkowski sum of a sharp cylinder of radius ``radius - edge_radius``
    whose end lies ``edge_radius`` above the face, and a ball of radius ``edge_radius``; the
    wedge is that of a sharp wedge whose apex lies ``edge_radius`` above the tip line, and a
    cylinder of radius ``edge_radius``. So each distance is the distance to a sharp core (to
    its end face, its rim circle, its side, its apex line or a flank plane) less
    ``edge_radius``. For the rim circle of radius ``c`` at the distance ``d`` in the plane of
    the axis, ``dn/dx = t t^T / d + (n_r / r) e_phi e_phi^T`` (``t`` the in-plane tangent,
    ``r`` the distance from the axis).
    """
    zero = wp.float64(0.0)
    down = wp.vec3d(zero, zero, wp.float64(-1.0))
    result = RigidContactPoint()
    if body.kind == RIGID_SPHERE:
        result = distance_to_point(x - body.point, 0)
        result.gap = result.gap - body.radius
        return result
    if body.kind == RIGID_PLATE:
        result.gap = body.point[2] - x[2]
        result.normal = down
        return result
    if body.kind == RIGID_PUNCH:
        core = body.radius - body.edge_radius
        core_end = body.point[2] + body.edge_radius
        dx = x[0] - body.point[0]
        dy = x[1] - body.point[1]
        r = wp.sqrt(dx * dx + dy * dy)
        face_depth = x[2] - body.point[2]
        if r <= core and (r == zero or body.radius - r >= face_depth):
            result.gap = -face_depth
            result.normal = down
            return result
        radial = wp.vec3d(dx / r, dy / r, zero)
        hoop = wp.vec3d(-dy / r, dx / r, zero)
        if r <= core:  # deep inside, nearer the side than the end face
            result.gap = r - body.radius
            result.normal = radial
            result.normal_gradient = wp.outer(hoop, hoop) / r
            return result
        if x[2] >= core_end:
            result.gap = r - core - body.edge_radius
            result.normal = radial
            result.normal_gradient = wp.outer(hoop, hoop) / r
            return result
        in_plane = (r - core) * radial + (x[2] - core_end) * wp.vec3d(zero, zero, wp.float64(1.0))
        d = wp.length(in_plane)
        n = in_plane / d
        t = wp.cross(hoop, n)
        result.gap = d - body.edge_radius
        result.normal = n
        result.normal_gradient = wp.outer(t, t) / d + (wp.dot(n, radial) / r) * wp.outer(hoop, hoop)
        return result
    # RIGID_WEDGE: the sharp core's apex line runs along y through (point[0], point[2] + rho).
    apex = wp.vec3d(body.point[0], x[1], body.point[2] + body.edge_radius)
    offset = x - apex
    side = wp.float64(1.0)
    if offset[0] < zero:
        side = wp.float64(-1.0)
    s = wp.sin(body.half_angle)
    c = wp.cos(body.half_angle)
    flank = wp.vec3d(side * s, zero, c)
    if wp.dot(offset, flank) <= zero:
        result = distance_to_point(offset, 1)
    else:
        result.normal = wp.vec3d(side * c, zero, -s)
        result.gap = wp.dot(offset, result.normal)
    result.gap = result.gap - body.edge_radius
    return result


@wp.kernel(module=FE_MODULE)
def rigid_contact_kernel(
    points: wp.array(dtype=wp.vec3d),
    displacement: wp.array(dtype=wp.vec3d),
    nodes: wp.array(dtype=wp.int32),
    diagonal_blocks: wp.array(dtype=wp.int32),
    node_problem: wp.array(dtype=wp.int32),
    bodies: wp.array(dtype=RigidBody),
    stiffness: wp.array(dtype=wp.float64),
    with_tangent: int,
    residual: wp.array(dtype=wp.vec3d),
    matrix_values: wp.array(dtype=wp.mat33d),
    energy: wp.array(dtype=wp.float64),
    contact_force: wp.array(dtype=wp.vec3d),
    node_force: wp.array(dtype=wp.vec3d),
    node_gap: wp.array(dtype=wp.float64),
):
    """Frictionless penalty contact of rigid bodies with the candidate nodes.

    Candidate ``i`` (node ``nodes[i]``) belongs to problem ``k = node_problem[i]`` and meets
    that problem's body ``bodies[k]`` with its penalty stiffness ``stiffness[k]`` (N/m); one
    problem: all zeros. A node that penetrates (signed distance ``g < 0``) gets the force
    ``f_c = -k g n`` along the body's outward normal ``n``: ``R -= f_c``, ``energy[k]`` gains
    ``k g^2 / 2`` (J) and the node's diagonal tangent block (``diagonal_blocks[i]``, BSR) gains
    ``d(-f_c)/dx = k (n n^T + g dn/dx)``. ``contact_force[k]`` sums the force on problem k's
    body (N); ``node_force[i]`` holds the force on ``nodes[i]`` (N; zero out of contact) and
    ``node_gap[i]`` its signed distance (m). The body's shape is evaluated in its frame
    (``x' = A x``, ``A = body.axes``) and the normal and its gradient turned back to the world
    (``n = A^T n'``, ``dn/dx = A^T (dn'/dx') A``).
    """
    i = wp.tid()
    node = nodes[i]
    problem = node_problem[i]
    k = stiffness[problem]
    body = bodies[problem]
    x = body.axes @ (points[node] + displacement[node])
    hit = rigid_contact_point(body, x)
    back = wp.transpose(body.axes)
    hit.normal = back @ hit.normal
    hit.normal_gradient = back @ hit.normal_gradient @ body.axes
    node_gap[i] = hit.gap
    if hit.gap >= wp.float64(0.0):
        node_force[i] = wp.vec3d()
        return
    force = -k * hit.gap * hit.normal
    node_force[i] = force
    wp.atomic_sub(residual, node, force)
    wp.atomic_add(contact_force, problem, force)
    wp.atomic_add(energy, problem, wp.float64(0.5) * k * hit.gap * hit.gap)
    if with_tangent != 0:
        block = k * (wp.outer(hit.normal, hit.normal) + hit.gap * hit.normal_gradient)
        wp.atomic_add(matrix_values, diagonal_blocks[i], block)


@wp.kernel(module=FE_MODULE)
def support_spring_kernel(
    rows: wp.array(dtype=wp.int32),
    columns: wp.array(dtype=wp.int32),
    block_ids: wp.array(dtype=wp.int32),
    spring_problem: wp.array(dtype=wp.int32),
    blocks: wp.array(dtype=wp.mat33d),
    displacement: wp.array(dtype=wp.vec3d),
    with_tangent: int,
    residual: wp.array(dtype=wp.vec3d),
    matrix_values: wp.array(dtype=wp.mat33d),
    energy: wp.array(dtype=wp.float64),
):
    """Linear springs from the nodes to the ground (an elastic foundation): a constant
    symmetric stiffness matrix ``S`` given by its nonzero 3x3 blocks.

    Entry ``e`` is the block ``S_ij = blocks[e]`` (N/m) of node ``i = rows[e]`` and node
    ``j = columns[e]`` of problem ``spring_problem[e]``: ``R_i += S_ij u_j``, the problem's
    ``energy`` gains ``u_i . S_ij u_j / 2`` (J) and the tangent's block ``block_ids[e]`` (BSR)
    gains ``S_ij``.
    """
    e = wp.tid()
    s = blocks[e]
    force = s @ displacement[columns[e]]
    row = rows[e]
    wp.atomic_add(residual, row, force)
    wp.atomic_add(energy, spring_problem[e], wp.float64(0.5) * wp.dot(displacement[row], force))
    if with_tangent != 0:
        wp.atomic_add(matrix_values, block_ids[e], s)


@wp.kernel(module=FE_MODULE)
def rigid_surface_contact_kernel(
    points: wp.array(dtype=wp.vec3d),
    displacement: wp.array(dtype=wp.vec3d),
    face_nodes: wp.array2d(dtype=wp.int32),
    face_blocks: wp.array2d(dtype=wp.int32),
    face_problem: wp.array(dtype=wp.int32),
    point_face: wp.array(dtype=wp.int32),
    point_shape: wp.array2d(dtype=wp.float64),
    point_area: wp.array(dtype=wp.float64),
    bodies: wp.array(dtype=RigidBody),
    stiffness: wp.array(dtype=wp.float64),
    with_tangent: int,
    residual: wp.array(dtype=wp.vec3d),
    matrix_values: wp.array(dtype=wp.mat33d),
    energy: wp.array(dtype=wp.float64),
    contact_force: wp.array(dtype=wp.vec3d),
    point_gap: wp.array(dtype=wp.float64),
):
    """Frictionless penalty contact of rigid bodies integrated over the surface's triangles
    (a segment-to-analytical-surface formulation).

    Quadrature point ``q`` lies on triangle ``f = point_face[q]`` (nodes ``face_nodes[f]``,
    3 or 6 of them: corners, then the mid-edge nodes of (0, 1), (1, 2), (2, 0)), with the
    triangle's shape functions ``N_a = point_shape[q, a]`` there and the reference area it
    stands for ``w = point_area[q]`` (m^2, the rule's weight times the reference area
    Jacobian). Its current position ``x = sum_a N_a (X_a + u_a)`` meets problem
    ``k = face_problem[f]``'s body at the signed distance ``g`` with outward normal ``n``;
    where ``g < 0`` the penalty ``eps = stiffness[k]`` (Pa/m) presses with the pressure
    ``-eps g``: the energy ``eps g^2 w / 2``, the nodal forces ``f_a = -eps g w N_a n``
    (``R -= f_a``) and the tangent blocks ``K_ab = eps w N_a N_b (n n^T + g dn/dx)`` at
    ``face_blocks[f, a * count + b]`` (BSR), ``count`` the triangle's node count.
    ``point_gap[q]`` holds ``g`` (m).
    """
    q = wp.tid()
    f = point_face[q]
    problem = face_problem[f]
    body = bodies[problem]
    count = face_nodes.shape[1]
    x = wp.vec3d()
    for a in range(count):
        node = face_nodes[f, a]
        x = x + point_shape[q, a] * (points[node] + displacement[node])
    hit = rigid_contact_point(body, body.axes @ x)
    point_gap[q] = hit.gap
    if hit.gap >= wp.float64(0.0):
        return
    back = wp.transpose(body.axes)
    normal = back @ hit.normal
    weight = stiffness[problem] * point_area[q]
    force = -weight * hit.gap * normal
    wp.atomic_add(contact_force, problem, force)
    wp.atomic_add(energy, problem, wp.float64(0.5) * weight * hit.gap * hit.gap)
    for a in range(count):
        wp.atomic_sub(residual, face_nodes[f, a], point_shape[q, a] * force)
    if with_tangent != 0:
        gradient = back @ hit.normal_gradient @ body.axes
        block = weight * (wp.outer(normal, normal) + hit.gap * gradient)
        for a in range(count):
            for b in range(count):
                scale = point_shape[q, a] * point_shape[q, b]
                wp.atomic_add(matrix_values, face_blocks[f, a * count + b], scale * block)
