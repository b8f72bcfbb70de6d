"""Array layouts of the rod kernels: every row and column by name.

The kernels of :mod:`solver.rod` (and the solver's private ones) take plain float and int
arrays; their users — the solver's wrappers, the sensing package, the batched environment —
name rows and columns with these constants and never read them by number. numba treats
module constants as compile-time constants.
"""

# Section array ``secf`` (6, ns): length (m), 1/EA, 1/GA (0: unshearable), 1/EI, EA, EI.
LEN, CA, CG, CI, EA, EI = range(6)
N_SECF = 6

# Tubes: ``tubes_i`` (n_tubes, 3) channel, first and last section spanned;
# ``tubes_f`` (n_tubes, 6) E·At (N), E (Pa), At/A, cos α, offsets a along d1 and b along d2 (m).
T_CHANNEL, T_FIRST, T_LAST = range(3)
TF_EAT, TF_E, TF_AREA_RATIO, TF_COS_ALPHA, TF_A, TF_B = range(6)

# Rest strains ``rest`` (3, ns): curvatures u1*, u2* (rad/m) and stretch v3*.
REST_U1, REST_U2, REST_V3 = range(3)

# Numeric parameters ``params`` of the path-following kernels: Newton tolerance, step
# limit, fold-scan bound, first and smallest continuation steps, Newton iterations, fold-scan
# points, branch-jump floor, and the cap on a predicted move (multiple shooting).
TOL, MAX_STEP, M_BOUND, DT0, DT_MIN, MAX_ITER, N_SCAN, JUMP, PREDICT_CAP = range(9)
N_PARAMS = 9

# Planar dead loads (ns, 4): internal force just proximal of each section end (n_end x, y;
# N) and distributed load per reference length (q x, y; N/m).
NEX, NEY, QX, QY = range(4)

# Planar record (N, 16): s, x, y, θ, m, internal force n (world x, y), strains v1, v3 and
# curvature u; then scratch: the first variations ∂(θ, m, x, y, v1, v3)/∂m0 of the RK4 pass
# that wrote the record, through which Newton applies its last correction
# (:func:`solver.kernels.planar.newton`, which leaves them NaN when it returns: a stored record
# holds NaN there). Adjacent pairs are the result's (N, 2) fields as slices.
S, X, Y, THETA, M, NX, NY, V1, V3, U, D_THETA, D_M, D_X, D_Y, D_V1, D_V3 = range(16)
N_COLUMNS = 16

# Spatial state (28,): position r, quaternion β of the directors, moment m (world), and the
# sensitivities δφ (3 columns of 3) and δm (3 columns of 3).
SP_R, SP_Q, SP_M, SP_DPHI, SP_DM = 0, 3, 7, 10, 19
NSTATE = 28

# Spatial dead loads (ns, 6): n_end (x, y, z; N) and q (x, y, z; N/m).
SL_N, SL_Q = 0, 3

# Contact record (N, 13): s, x, y, θ, m, n_x, n_y, v1, v3, u — the columns of the planar
# record, in its places, so that what reads a planar record's backbone reads this one's —
# then the contact load per reference length f_x, f_y and the penetration.
C_S, C_X, C_Y, C_TH, C_M, C_NX, C_NY, C_V1, C_V3, C_U, C_FX, C_FY, C_PEN = range(13)
C_COLUMNS = 13

# Multiple-shooting segment table (M, 5): section, first local step, steps, ends the
# section, first recorded row of the section.
SEG_SECTION, SEG_FIRST, SEG_STEPS, SEG_END, SEG_ROW0 = range(5)

# Obstacles (k, 4): centre x, centre y, radius (m), penalty stiffness (N/m²).
CX, CY, RADIUS, STIFFNESS = range(4)

# A multiple-shooting homotopy end ("level") is a tuple (p, q, plate, target, discs, mu,
# friction[, self-friction]): channel pressures (n_channels,), distributed loads (ns, 2),
# endplate weights (ns, 2), tip target n(L⁻), M_tip (3,), obstacles (k, 4), each obstacle's
# Coulomb coefficient (k,) and the friction samples (below; no rows: no friction); a planar
# level then has the self-contact friction samples (below; no rows: none). A ramp
# interpolates the first five; mu and the samples are the tangential state it carries
# (docs/design.md §9.1).
L_P, L_Q, L_PLATE, L_TARGET, L_DISCS, L_MU, L_FRICTION, L_SELF_FRICTION = range(8)

# Friction samples (rows, NEAR_SUBSTEPS + 1, k, N_FS): per RK4 step of a contact layout (by
# the record row of the step's start node), per node of the step's refinement near an
# obstacle and per obstacle: the anchor the sample is stuck to (m, relative to the
# obstacle's centre or axis point; NaN: none); then, written by a pass that records, at its
# state: the return-mapped anchor, the friction impulse on the arm (N), the sample's position
# (m) and its slip from the anchor (m); and the energy its slip dissipated along the path so
# far (J). Planar samples use the x, y of each 3-vector.
FS_A, FS_NEW, FS_F, FS_R, FS_SLIP, FS_WORK = 0, 3, 6, 9, 12, 13
N_FS = 14

# Self-contact friction samples (M, segment steps + 1, SUBPOINTS, N_FS): per point at which
# the self-contact law is sampled — segment, RK4 node of the segment (its canonical slot,
# solver.kernels.self_contact.canonical_slot) and point of the step from it (0: the node) —
# the ``FS_*`` columns of the obstacles' samples, with the anchor an arc length: FS_A and
# FS_NEW hold the reference arc length s' (m) of the partner's material point the point
# sticks to (NaN: none; their other two entries 0); FS_F the friction impulse on the point
# (N), FS_R its position (m).

# The multiple-shooting layout tuple ``grid``: base angle θ0, segment table, section array,
# RK4 steps per section (ns,), section start arc lengths (ns,) and the self-contact
# parameters (3 + ns,): penalty stiffness (N/m²; 0: off), exclusion length along the arc
# (m), Coulomb coefficient μ between parts of the arm, then each section's half-thickness (m).
G_THETA0, G_SEGS, G_SECF, G_STEPS, G_START, G_SELF = range(6)
SC_K, SC_EXCLUSION, SC_MU, SC_HALF = range(4)

# Self-contact, worked out from the shooting nodes at every residual: the backbone of each
# segment at its RK4 nodes, (M, segment steps + 1, 15): x, y, arc length s (m),
# half-thickness (m), then the slope r' (2) and its derivative r'' (2; 1/m) after the node
# and the same before it (they differ by the shear and stretch of a point load on the
# node), a lower bound on the node's distance to the other parts (m) and the node's x, y
# (m) when that bound was worked out (see solver.kernels.self_contact.self_loads); per segment
# (M, 4) a bounding circle's centre x, y and radius (m; negative: not built) and whether it
# is in contact (0 or 1); and per RK4 node (M, segment steps + 1, 8) the point load the
# node carries (N), that load per length (N/m), the node's penetration (m) and the load's
# stiffness ∂F/∂r (symmetric 2×2: k00, k01, k11; N/m) with the other part held fixed, and
# the point moment (N m) self-contact friction puts on it (its forces act at the contact
# points, not on the backbone).
(P_X, P_Y, P_S, P_H, P_DXA, P_DYA, P_EXA, P_EYA, P_DXB, P_DYB, P_EXB, P_EYB, P_CLEAR, P_X0,
 P_Y0) = range(15)
N_POINT = 15
B_X, B_Y, B_R, B_TOUCH = range(4)
N_BOUNDS = 4
SELF_FX, SELF_FY, SELF_QX, SELF_QY, SELF_PEN, SELF_K00, SELF_K01, SELF_K11, SELF_M = range(9)
N_SELF = 9

# Spatial contact state (13,): position r, quaternion β of the directors, internal force n
# and moment m (world frame); its tangent coordinates (12,) replace β by a world-frame
# rotation vector δφ (``CT_*``).
CS_R, CS_Q, CS_N, CS_M = SP_R, SP_Q, 7, 10  # r and β where the dead-load state has them
N_CSTATE = 13
CT_R, CT_PHI, CT_N, CT_M = 0, 3, 6, 9
N_CTANGENT = 12

# Spatial obstacles (k, 8): a point, an axis direction (a cylinder; zero: a sphere about the
# point), the contact radius (m) and the penalty stiffness (N/m²).
O_P, O_AXIS, O_RADIUS, O_STIFFNESS = 0, 3, 6, 7
N_OBSTACLE = 8

# The spatial contact layout tuple ``grid``: base orientation quaternion (4,), segment table,
# section array, RK4 steps per section (ns,), 1/GJ (ns,) and section start arc lengths (ns,).
GS_QUAT0, GS_SEGS, GS_SECF, GS_STEPS, GS_CJ, GS_START = range(6)
