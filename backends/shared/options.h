/* options.h -- the tracer core's compile-time options (docs/design.md section 4), each with its default
 * where the host does not set it, and the few derived from them. The first of the tracer files
 * (backends.shared.TRACER_FILES): every file after it may test any of them.
 *
 * Compile-time defines (engine.packed.Features.defines() and the backend):
 *   HAS_PORTALS        linked portals exist: portal search and teleport
 *   HAS_ABERRATIONS    aberration boxes exist: box faces, active box, transitions
 *   HAS_TEXTURES       some material samples the texel atlas (TEXEL(i))
 *   HAS_SMOOTH         some instance shades with vertex normals (TRIANGLE_NORMAL(i))
 *   HAS_CHECKER        some material has a checker (cell > 0); 1 where not given
 *   SHADE              the colour is wanted: shade the hit (and trace its shadow rays); 0 for a frame of
 *                      depth, instance and events only, which Embree's pairing times; 1 where not given
 *   HAS_METRIC HAS_RADIAL HAS_ADDITIVE  the box modes present: only their rules compile
 *   HAS_LIGHTS         Light entities exist (the lights table), else the implicit sun along light_dir
 *   HAS_SHADOWS        a light casts shadows: shadow rays take the journey (journey.h, shadow_lit)
 *   MAX_EVENTS         events a ray may take (the settings' max_events, which it bounds)
 *   REAL_IS_DOUBLE     trace in double precision
 *   EDGE_FALLBACK_FP64 float tracer: recompute an edge function that is exactly
 *                      0 in double (exact: a product of two floats fits a double)
 *   WORLD_FP64         float tracer: world-space checker coordinates in double
 *                      (the packed origin can be 1e5 away while cells are 0.05)
 *   BRUTE_FORCE        test every triangle of an instance (benchmarks only)
 *   BVH_STACK_SIZE     traversal stack; the host checks every tree fits
 *   BVH_WIDTH          2: binary nodes, one triangle at a time; 4: 4-wide nodes (child boxes SoA,
 *                      slabbed with 4-vector ops) whose leaves are blocks of 4 triangles tested at
 *                      once; 8 (OpenCL C only, real8): 8-wide nodes, the same blocks (layout.h;
 *                      the packer's bvh_width, from the table's dtype)
 *   BVH_COMPACT        1 with BVH_WIDTH 2: compact records, both children's boxes (16-bit grid) and
 *                      links in one 32-byte record (the packer's bvh_compact; GLSL on llvmpipe)
 *   USE_TLAS           find instances through the top-level tree (tlas_nodes), not a loop over all
 *   TLAS_STACK_SIZE    its traversal stack; the host sizes it to the tree's depth
 *   PORTAL_TREE        find the portal a ray passes through the tree over portals (space_nodes), not a
 *                      loop over all; BOX_TREE the same for box faces and the box holding a point; the
 *                      host sets them above a few portals / boxes, where the tree is faster
 *   SPACE_WIDE         1: the rays walk those trees' 4-wide forms (space_nodes from space_roots.z / .w,
 *                      engine/space_wide.py; OpenCL); 0: the binary trees
 *   SPACE_STACK_SIZE   their traversal stack; the host sizes it to the deeper tree's depth
 *   PORTAL_COUNT       the live portal rows, BOX_COUNT the box rows, where the loops find them (no tree) and
 *                      the host compiles the count in (GLSL: llvmpipe then unrolls the loops, no settings
 *                      load); -1 (default): the loops read the settings row's counts
 *   SKIP_CLEAR_SEARCH  1: skip the mesh searches the host's clearances prove empty (box rows' rot0.w,
 *                      the camera row's lens.z with CAMERA_CLEAR_SEARCH 1); FACE_NEXT_BOX 1: the
 *                      box after a face of a box alone (rot1.w) from the face, not the loop
 *                      (engine/box_clearance.py); OWN_BOX_FACES 1: the face search on a leg inside a
 *                      box alone is that box's own faces, not the tree's walk; 0 for A/B only;
 *                      LEFT_BOX_GAP 1: a leg leaving a box's face walks the box tree only from that box's
 *                      gap on (boxes.h, box_face_from; OpenCL's default, 0 on GLSL, where llvmpipe runs
 *                      the left box's faces for every lane)
 *                      LEFT_PORTAL_GAP 1: a leg that comes out of a portal walks the portal tree only from
 *                      that quad's gap (portal rows' meta.z) on (portals.h, portal_from; both backends)
 *   CAMERA_BOX_ENTRY   0: the host's camera row says no primary ray starts in a box (size.z = -1), so the
 *                      transition at the camera compiles out; FACE_NEXT_ONLY 1: the host proved FACE_NEXT_BOX's
 *                      gap test true for every face event of the frame, so the containing_box loop after a face
 *                      compiles out (both backends, per frame: llvmpipe would run that code masked for every
 *                      ray, and PoCL, knowing the first leg starts in no box, folds its state into constants)
 *   SPACE_WALK         1: the legs those clearances prove free of meshes are crossed in a loop of their
 *                      own before each mesh search (journey.h: llvmpipe runs a loop's body masked for all
 *                      its lanes; no cost on PoCL); 0: one pass of the event loop per leg, for A/B only
 *
 */

#ifndef MAX_EVENTS
#define MAX_EVENTS 16
#endif
#ifndef HAS_PORTALS
#define HAS_PORTALS 0
#endif
#ifndef HAS_ABERRATIONS
#define HAS_ABERRATIONS 0
#endif
#ifndef HAS_LIGHTS
#define HAS_LIGHTS 0
#endif
#ifndef HAS_SHADOWS
#define HAS_SHADOWS 0
#endif
#ifndef HAS_TEXTURES
#define HAS_TEXTURES 0
#endif
#ifndef HAS_SMOOTH
#define HAS_SMOOTH 0
#endif
#ifndef HAS_CHECKER
#define HAS_CHECKER 1
#endif
#ifndef SHADE
#define SHADE 1
#endif
#ifndef REAL_IS_DOUBLE
#define REAL_IS_DOUBLE 0
#endif
#ifndef EDGE_FALLBACK_FP64
#define EDGE_FALLBACK_FP64 0
#endif
#ifndef WORLD_FP64
#define WORLD_FP64 0
#endif
#ifndef BRUTE_FORCE
#define BRUTE_FORCE 0
#endif
#ifndef BVH_STACK_SIZE
#define BVH_STACK_SIZE 64
#endif
#ifndef USE_TLAS
#define USE_TLAS 1
#endif
#ifndef TLAS_STACK_SIZE
#define TLAS_STACK_SIZE 32
#endif
#ifndef PORTAL_TREE
#define PORTAL_TREE 0
#endif
#ifndef BOX_TREE
#define BOX_TREE 0
#endif
#ifndef SPACE_STACK_SIZE
#define SPACE_STACK_SIZE 16
#endif

#ifndef PORTAL_COUNT
#define PORTAL_COUNT -1
#endif
#ifndef BOX_COUNT
#define BOX_COUNT -1
#endif
#define PORTAL_ROWS (PORTAL_COUNT >= 0 ? PORTAL_COUNT : SETTINGS.counts.z)
#define BOX_ROWS (BOX_COUNT >= 0 ? BOX_COUNT : SETTINGS.counts.y)

#ifndef HAS_METRIC
#define HAS_METRIC 0
#endif
/* Shortcuts the host's box clearances prove exact (engine/box_clearance.py, docs/semantics.md section 14);
 * 0 turns one off (A/B benchmarks, and tests that the frames are bit-identical either way). Measured
 * (800x800, CPU time): -16 ms OpenCL, -29 ms GLSL per frame on ten-boxes-aberration, -6 ms GLSL on
 * ten-boxes-portals. */
#ifndef SKIP_CLEAR_SEARCH
#define SKIP_CLEAR_SEARCH 1
#endif
#ifndef FACE_NEXT_BOX
#define FACE_NEXT_BOX 1
#endif
#ifndef OWN_BOX_FACES
#define OWN_BOX_FACES 1
#endif
#ifndef CAMERA_CLEAR_SEARCH
#define CAMERA_CLEAR_SEARCH 1
#endif
#ifndef CAMERA_BOX_ENTRY
#define CAMERA_BOX_ENTRY 1
#endif
#ifndef FACE_NEXT_ONLY
#define FACE_NEXT_ONLY 0
#endif
/* A camera ray's first leg searched with its tile's list before the event loop (journey.h), where later legs
 * walk the tree; 0 searches it in the loop (A/B, and tests that the frames are the same). */
#ifndef FIRST_LEG_APART
#define FIRST_LEG_APART (HAS_SPACE && INSTANCE_TILES && !INSTANCE_TILES_ONLY)
#endif
#ifndef LEFT_BOX_GAP
#ifdef __OPENCL_VERSION__
#define LEFT_BOX_GAP 1
#else
#define LEFT_BOX_GAP 0
#endif
#endif
#ifndef LEFT_PORTAL_GAP
#define LEFT_PORTAL_GAP 1
#endif
#ifndef SPACE_WALK
#define SPACE_WALK 1
#endif
#ifndef HAS_RADIAL
#define HAS_RADIAL 0
#endif
#ifndef HAS_ADDITIVE
#define HAS_ADDITIVE 0
#endif
/* Anything that bends or teleports rays: the journey has more than one leg. */
#define HAS_SPACE (HAS_ABERRATIONS || HAS_PORTALS)
/* Box modes that bend the perceived direction w (entry and exit rules). */
#define HAS_BENDING (HAS_RADIAL || HAS_ADDITIVE)
/* Camera rays traced in two dispatches (GLSL, backends/glsl/split.py): 1 traces every pixel's first leg and
 * finishes the rays it ends, queueing the others; 2 takes the queued rays on from their first leg's end. On
 * llvmpipe a branch runs for every lane and a loop's body at least once, active lanes or not, so the event
 * loop cost a pass for every pixel; the queue gathers the rays that need it. 0: one dispatch. */
#ifndef SPLIT_PASS
#define SPLIT_PASS 0
#endif
#if SPLIT_PASS && !FIRST_LEG_APART
#error "SPLIT_PASS needs the first leg searched apart from the event loop (FIRST_LEG_APART)"
#endif
#if SPLIT_PASS && HAS_SHADOWS
#error "SPLIT_PASS: the first pass has no event loop for shadow rays"
#endif
/* Camera rays eight at a time, a 4x2 block of pixels a work-item (OpenCL, backends/opencl/packet.cl): the
 * host sets it for the frames that qualify (backends/opencl/packets.py). 0: one ray a work-item. */
#ifndef PACKET_PRIMARY
#define PACKET_PRIMARY 0
#endif
/* Work-items over a list of view tiles (OpenCL's tile_order argument, -1 for padding), each a tile's pixel or,
 * with PACKET_PRIMARY, its 4x2 block: a frame with portals traces the tiles whose first legs meet none with
 * the Euclidean variant and the others with its own (backends/opencl/tile_order.py). 0: the image's grid. */
#ifndef TILE_ORDER
#define TILE_ORDER 0
#endif
#if TILE_ORDER && !(INSTANCE_TILES || VIEW_TILES)
#error "TILE_ORDER: the work-items' tiles are the view tiles"
#endif
