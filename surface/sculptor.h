#pragma once
// Incremental sculpting of a 2-manifold surface in a 3D Delaunay triangulation (Litvinov and
// Lhuillier, BMVC 2013, sections 3–5). The input is the keyframe stream of docs/design.md §7; the
// output is δO, the border of the carved free space O, as a triangle mesh oriented towards O.

#include <Eigen/Core>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "calib/ids.h"
#include "calib/ply.h"
#include "surface/delaunay.h"
#include "surface/observed_mesh.h"

namespace omni {

// A ray of a point: the keyframe that observed it and the optical centre it starts from
// (the keyframe centre in central mode, the observing camera's centre otherwise).
struct SurfaceRay {
  KeyframeId keyframe;
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
};

struct SurfacePoint {
  PointId id;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  std::vector<SurfaceRay> rays;
};

// A direction in which keyframe t's image sees no structure (the sky): from an optical centre,
// unit direction. Carves the cells it crosses up to SculptorOptions::free_ray_length_factor · r.
struct SurfaceFreeRay {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();
};

// The only sfm→surface contract (docs/design.md §7): the points P_t of keyframe t and the
// directions that see nothing (none from the SfM today).
struct SurfaceKeyframe {
  KeyframeId id;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  // c_t
  std::vector<SurfacePoint> points;
  std::vector<SurfaceFreeRay> free_rays;
};

// The enclosing set E of paper §4.1, which O is shrunk out of before the new points go in.
enum class EnclosingMode {
  kBall,           // the paper: the cells inside B_{r+l}(c_{t+1})
  kConflictZones,  // the paper's future work (§6): the union D of the conflict zones of the new
                   // points (found without inserting them) plus enclosing_margin rings of cells,
                   // widened after the shrink where O still meets D (enclosing_rounds)
};

// Step 6 of paper §4.6, first part: genus refinement ("handle removal", ref. [21]) of O ∩ E.
// Groups of cells of F \ O are added to O at once while δO stays a 2-manifold (general test at
// every vertex of the group, rolled back on failure), most crossed cells first: the cells around
// an edge, then connected groups of F \ O. No Steiner point is added (T stays Delaunay, §4.6).
struct GenusRefinementOptions {
  bool enabled = true;       // on the cells of E ∪ N ∪ the cells crossed by new rays
  bool edge_stars = true;    // try the F \ O cells around each edge at once
  int max_group_cells = 32;  // largest connected group of F \ O cells tried at once (0: none)
  // Test reference: no memo of the groups that failed since O last changed, vertices tested in
  // index order. Same outcome, slower.
  bool reference = false;
  std::string Check() const;
};

// Step 6 of paper §4.6, second part: incremental smoothing (ref. [20]) of the output surface. The
// Delaunay vertices never move; smoothed positions of the δO vertices are kept beside T and
// recomputed, in each keyframe, for the δO vertices whose umbrella changed and their neighbours,
// inside the enclosing ball only: peak removal, then Taubin λ|μ steps of a feature-preserving
// (bilateral) normal Laplacian. A move that turns an
// incident triangle against its free side, or makes it meet a nearby δO triangle, is rejected.
struct SmoothingOptions {
  bool enabled = true;
  // When the smoothing runs. T keeps the SfM positions and the sculpting never reads the
  // smoothed ones, so the smoothing can wait: off, each keyframe only notes the vertices whose
  // umbrella may have changed, and they are smoothed together when a mesh or a position is
  // taken from the sculptor (ExtractMesh, ExtractObservedMesh, SurfacePosition): once at the
  // end of a run, or at each snapshot. On: every keyframe smooths its own vertices (the
  // incremental smoothing of the paper), so that δO is smooth after each keyframe whatever
  // the caller takes.
  bool every_keyframe = false;
  int taubin_steps = 3;  // λ|μ pairs (Taubin, SIGGRAPH 1995: shrink-free low-pass smoothing)
  double lambda = 0.5;
  double mu = -0.53;
  // A vertex farther from the plane of its umbrella than peak_factor times its mean edge length
  // is a peak: moved to the centroid of its neighbours before the Taubin steps.
  double peak_factor = 0.75;
  // The Laplacian moves a vertex along its umbrella normal by the mean height of its neighbours
  // over its tangent plane, each weighed by exp(−h²/2σ²) with σ = feature_sigma times its mean
  // edge length: neighbours across a crease (a wall meeting the ground) barely pull.
  double feature_sigma = 0.1;
  // A vertex with an umbrella triangle turned more than this from the umbrella normal is on a
  // crease or a corner: the Taubin steps leave it where it is. 180: off (30° froze most noisy
  // vertices, whose sliver triangles turn far, and smoothed nothing on the test walls).
  double crease_angle_deg = 180.0;
  // Rejects a move that leaves an incident triangle with an area below this fraction of its
  // squared longest edge (a near-degenerate triangle), besides flips.
  double min_triangle_shape = 1e-4;
  // Test reference for the local intersection checks: each check gathers the δO triangles
  // around the vertex anew and tests every pair whose boxes meet the umbrella's (no per-keyframe
  // cache, no per-triangle box filter, no inexact side pre-check). Same positions, slower.
  bool reference_checks = false;
  std::string Check() const;
};

// How the old rays are re-traced over the new cells N (paper §4.4). All modes give the same
// counters; they differ in the rays and cells visited.
enum class OldRayTracing {
  kAllRays,      // every old ray, walked whole from its point (brute force, the reference)
  kWholeWalks,   // the old rays in the voxels of a grid that N's border touches or starting at
                 // a vertex of N, walked whole from their point
  kNewCellRuns,  // the same rays, walked only inside N: from their point when it is a vertex
                 // of N and from each clean crossing of N's border (whole walk otherwise)
};

// How kConflictZones widens E where the shrink left cells of O in D (SculptorOptions).
enum class EnclosingWidening {
  kRings,        // the cells of O within enclosing_margin + enclosing_round_rings · 2^k facet
                 // steps through O of those cells (round k = 0, 1, ...)
  kVertexStars,  // the cells of O incident to their vertices, then to the vertices of the cells
                 // added, k + 1 vertex rings in round k: what the several-at-once shrink needs
};

struct SculptorOptions {
  // s, the unit of the bounds below (paper §5.1: the mean distance between consecutive keyframe
  // centres); 0: measured on the first init_keyframes keyframes, as that mean distance or, when
  // larger, reach_quantile's reach over max_ray_length_factor.
  double scale = 0.0;
  // The measured s is at least the reach of the first keyframes' points over
  // max_ray_length_factor: their distance to their keyframe centre at this quantile, over the
  // points that pass the aperture filter (their triangulation angle, i.e. their depth against
  // the baseline of the cameras that see them, makes them certain enough). So the bounds r, l,
  // the ground and the Steiner step follow where the points are, not the keyframe spacing
  // alone: with keyframes denser than the points' depth asks for (a COLMAP model of every
  // frame, 0.4 m apart), r = 15 s would drop most points as too far. Scale-free, so it holds in
  // any world frame. 0: off (the paper, s the keyframe spacing).
  double reach_quantile = 0.97;
  // Step of the Steiner grid in units of s (paper §5.1: 15 s). The tetrahedra diameter bound
  // l of §3.3 is the voxel diagonal.
  double steiner_step_factor = 15.0;
  // r of §3.3 in units of s: points farther than r from their keyframe centre are filtered
  // out (paper §5.1: ‖p − c_t‖ ≤ 15 s).
  double max_ray_length_factor = 15.0;
  // A point closer than min_point_separation_factor × s to a vertex is that vertex (counted
  // as a duplicate): a COLMAP model holds points a few nanometres apart, which round to one
  // position in the float coordinates of the PLY files and make zero-area triangles there, and
  // give the triangulation needle cells. SfM points that close are one point. 0: exact
  // duplicates only.
  double min_point_separation_factor = 1e-3;
  // A point is also that vertex when the two are less than this many pixels apart as the
  // nearest of the point's ray origins sees them (an angle: min_point_separation_pixels ×
  // pixel_angle times the distance to that origin): two points the cameras cannot tell apart.
  // Scale-free and resolution-aware where the factor above is neither; 0: off.
  double min_point_separation_pixels = 3.0;
  // The angle a pixel spans (radians) in the finest camera that gave the points, set by the
  // caller from the rig (Rig::FinestPixelAngle); 0: unknown, min_point_separation_pixels unused.
  double pixel_angle = 0.0;
  // A point merged into a vertex (a duplicate above) keeps its rays: they are traced from that
  // vertex, as the rays of a point there. false: the duplicate is dropped with its rays.
  bool duplicate_rays = true;
  // Point filters of §5.1.
  bool filter_points = true;
  // Reject (p − c_t)·up < −b, b = max(below_ground_factor · s, g + ground_margin_factor · s)
  // with g the depth of the ground under the keyframe centres, measured on the first keyframes'
  // points with a wide aperture: minus their height (p − c_t)·up at ground_quantile (0: no g,
  // the paper's −3 s alone). The paper's 3 s assumes cameras about that high; a rig 4 m above
  // the ground with keyframes 0.7 m apart would otherwise lose the whole ground.
  double below_ground_factor = 3.0;
  double ground_quantile = 0.05;
  double ground_margin_factor = 1.0;
  // Aperture filter: keep a point only when two of its rays are more than this many degrees
  // apart. The paper's 10° dropped half of the SfM's points (most tracks span two keyframes,
  // 2.3 m apart) and with them most of the rays that carve; 5° raises the pixel F@0.5 of
  // `reconstruct` on the short drive from 0.70 to 0.80 and lowers the tail, and changes little
  // with the perfect SfM (figures.md F29).
  double min_aperture_deg = 5.0;
  // The vertical direction v of §5.1, in the world frame of the keyframes (z for the drives of
  // synth/; pipeline/world_up.h estimates it for a world frame without an up axis).
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  // The first init_keyframes keyframes measure s; with batch_init they are sculpted at once
  // (paper §5.1: T_40, F_40, O_40), otherwise one by one like the others.
  int init_keyframes = 40;
  bool batch_init = true;
  // After the first ones, keyframes are sculpted this many at a time: their points inserted
  // together and their rays traced once, after all the insertions (a keyframe's rays are then
  // not re-traced over the next one's new cells, and the steps' fixed costs are shared). The
  // surface lags by up to keyframes_per_step − 1 keyframes; Finish sculpts the last ones in a
  // smaller step. 1: each keyframe as it comes (the paper). With the ball E, E is the union of
  // the step's balls.
  int keyframes_per_step = 1;
  // With a known scale, still buffer the first init_keyframes keyframes and sculpt them in one
  // batch (with batch_init): the re-sculpt of a map corrected by a loop closure keeps the first
  // sculpting's s (pipeline/). Otherwise a known scale sculpts each keyframe as it comes.
  bool batch_with_known_scale = false;
  // The conflict zones by default: on the paper drive (surface --from-gt) steps 1-5 take 0.55 to
  // 0.7 of the ball's time, with higher F-scores and fewer errors > 6 m (docs/design.md).
  EnclosingMode enclosing = EnclosingMode::kConflictZones;
  int enclosing_margin = 2;  // kConflictZones: rings of neighbouring cells added around D
  // kConflictZones: where the shrink left cells of O in D (it is blocked by the manifold tests:
  // such a cell has all four vertices on δO and the star of one of them leaves E), E is widened
  // (enclosing_widening) and O shrunk again, at most enclosing_rounds times; the points whose
  // conflict zone still meets O are then rejected (§4.3).
  int enclosing_rounds = 4;
  int enclosing_round_rings = 2;
  EnclosingWidening enclosing_widening = EnclosingWidening::kVertexStars;
  int enclosing_star_rings = 1;  // kVertexStars: vertex rings of the first round (+1 per round)
  // kConflictZones: after the growth, the cells of F \ O around the vertices whose δO umbrella
  // changed in the keyframe are grown too, repeated while it changes O, at most this many times
  // (0: the growth region is E ∪ N ∪ the cells crossed by new rays only).
  int grow_closure_rounds = 8;
  // kConflictZones: the several-at-once shrink (§4.7) tries only the vertices of the cells of O
  // in D (what must leave O before the insertions), not those of all of O ∩ E.
  bool targeted_shrink = true;
  // Re-tracing of the old rays over the new cells N (§4.4); every mode gives the same counters.
  OldRayTracing old_rays = OldRayTracing::kNewCellRuns;
  // Voxel side of the grid that holds the old rays and the border of N, in units of s.
  double ray_grid_step_factor = 1.0;
  // Several-at-once passes (paper §4.5, §4.7): at most this many sweeps over the vertices of
  // the enclosing set per keyframe.
  int max_vertex_passes = 4;
  // For tests: before each insertion, every cell of O is tested for conflict with the point
  // by brute force (the point in its circumsphere, CGAL's perturbed predicate), independently of
  // the conflict-zone search, and the insertions that meet O are counted
  // (KeyframeStats::insertions_meeting_o). Costs O(|O|) per point.
  bool verify_insertions = false;
  // Test reference for steps 2 and 5: no memo of failed manifold tests (a failed subtraction or
  // addition test, a failed several-at-once attempt), CGAL's incident_cells. Same O, slower.
  bool reference_manifold_tests = false;
  // Step 6 (paper §4.6).
  GenusRefinementOptions genus;
  SmoothingOptions smoothing;
  // The observed part of δO (ExtractObservedMesh, surface.ply); the sculpting ignores it.
  ObservedMeshOptions observed;

  // Carving beyond the paper (docs/design.md §6).
  // A cell that no ray crossed with at least this many of its four neighbours in F joins F (its
  // counter set to 1) before the growth: matter that no point bounds, enclosed by carved space
  // (the thin cells in front of a wall between the rays' ends, which a ray ending exactly at a
  // vertex does not cross). 0: off; 2, 3 or 4. On the short drive (--from-gt) 3 halves the
  // errors above 1 m in front of the ground truth, 2 carves into the walls (docs/figures.md F14).
  int enclosed_free_neighbours = 3;
  int enclosed_free_rounds = 1;  // repeated on the neighbours of the cells that joined F
  // The keyframes' free rays (SurfaceFreeRay) carve the cells they cross from their origin up to
  // this times r, once, when their keyframe is sculpted (they are not re-traced over later new
  // cells). 0: ignored.
  double free_ray_length_factor = 1.0;
  // The rays of a point that the aperture filter drops still carve, short of the point: its
  // depth along a ray is uncertain by about its angular error over its aperture α (the widest
  // angle between two of its rays), so each ray carves from its origin up to the fraction
  // 1 − uncertain_ray_margin_deg / α of the way, once, when the keyframe is sculpted (not
  // re-traced over later new cells); none when that fraction is below
  // uncertain_ray_min_fraction. 0: off (the paper drops such points whole).
  double uncertain_ray_margin_deg = 0.0;
  double uncertain_ray_min_fraction = 0.25;

  std::string Check() const;
};

// One row per step: a keyframe, or keyframes_per_step of them, or the batch initialisation
// (batch = true).
struct KeyframeStats {
  KeyframeId keyframe;  // the last keyframe of the step
  bool batch = false;
  // Keyframes sculpted in this step (SculptorOptions::keyframes_per_step; the batch: all of it).
  size_t keyframes = 1;
  size_t points_in = 0;         // points received
  size_t points_filtered = 0;   // removed by the §5.1 filters: the sum of the four below
  size_t points_added = 0;      // inserted in T
  size_t points_rejected = 0;   // conflict zone met O (§4.3)
  size_t points_duplicate = 0;  // an existing vertex, or within the separation of one
  size_t points_merged = 0;     // of the duplicates, those whose rays were kept (duplicate_rays)
  size_t steiner_added = 0;
  size_t rays_new = 0;                           // rays of the new points, traced fully
  size_t rays_old = 0;                           // older rays re-traced over N (§4.4)
  size_t cells_e = 0;                            // |E|
  size_t cells_n = 0;                            // |N|
  size_t o_left_in_e = 0;                        // |O ∩ E| after shrinking
  size_t cells_t = 0, cells_f = 0, cells_o = 0;  // finite cells of T, F, O after the keyframe
  size_t triangles = 0;                          // triangles of δO
  double ms_steiner = 0, ms_enclose = 0, ms_shrink = 0, ms_insert = 0, ms_rays = 0, ms_grow = 0,
         ms_total = 0;
  // Step 6 (paper §4.6). Genus refinement: cells of F ∩ E outside O before and after it, groups
  // added, and the change of the Euler characteristic χ of δO it made (the genus change is
  // −Δχ/2 when no component of δO was merged or closed by it).
  size_t genus_free_before = 0, genus_free_after = 0, genus_groups = 0;
  long genus_euler_change = 0;
  // Smoothing: δO vertices recomputed, moves rejected (flip or local intersection).
  size_t smoothed_vertices = 0, smoothing_rejected = 0;
  // Of the smoothing's intersection checks run in parallel first, those taken again because a
  // vertex they read was sent back meanwhile. Not in the CSV row.
  size_t smoothing_prechecked = 0, smoothing_rechecked = 0;
  double ms_genus = 0, ms_smooth = 0;
  // Step 4 details (§4.4): old rays proposed by the ray index before the exact selection, cells
  // visited by the re-traced old rays, and the milliseconds of the selection (which runs beside
  // the tracing of the new rays, inside ms_rays) and of their walks.
  size_t rays_old_candidates = 0, old_walk_cells = 0;
  double ms_rays_select = 0, ms_rays_old = 0;
  // The §5.1 filters one by one, each point counted by the first that removes it, in this order:
  // not usable (a non-finite position or no ray), below the ground ((p − c_t)·v < −3 s), too far
  // (‖p − c_t‖ > 15 s), aperture (no two rays more than min_aperture_deg apart).
  size_t points_invalid = 0, points_filtered_ground = 0, points_filtered_length = 0,
         points_filtered_aperture = 0;
  // The border facets of N indexed for the old rays, and those left out because no ray crossed
  // the cell outside them (NewCellBorder::Build).
  size_t old_ray_facets = 0, old_ray_facets_uncrossed = 0;
  // The crossings of N's border found for the candidate old rays (internal::EntriesWork): the
  // queries, the fine voxels they walked, the border facets they tested and those of them that
  // the plane filter in doubles did not settle.
  size_t old_ray_queries = 0, old_ray_query_voxels = 0, old_ray_facet_tests = 0,
         old_ray_plane_passes = 0;
  // kConflictZones: widening rounds of E done after the first shrink, and the cells they added.
  size_t enclose_rounds = 0, cells_e_added = 0;
  // kConflictZones: cells of F \ O added to the growth region around the changes of δO
  // (SculptorOptions::grow_closure_rounds).
  size_t cells_grow_extra = 0;
  // Step 6 work: the cells given to the genus refinement, the δO vertices examined by the
  // smoothing (those whose umbrella may have changed).
  size_t cells_active = 0, smoothing_candidates = 0;
  // With SculptorOptions::verify_insertions: points inserted although their conflict zone met O
  // (must be 0, §4.3). Not in the CSV row.
  size_t insertions_meeting_o = 0;
  // Steps 2 and 5: manifold tests not run again because they had failed on unchanged stars
  // (subtraction/addition tests, several-at-once attempts; 0 with reference_manifold_tests).
  // Not in the CSV row.
  size_t single_tests_skipped = 0, attempts_skipped = 0;
  // SculptorOptions::enclosed_free_neighbours: cells that joined F without a ray.
  size_t cells_enclosed_free = 0;
  double ms_enclosed_free = 0;  // their search, inside ms_grow
  // SurfaceKeyframe::free_rays traced, and the cells they crossed (inside ms_rays). Not in the
  // CSV row.
  size_t rays_free = 0, free_ray_cells = 0;
  // SculptorOptions::uncertain_ray_margin_deg: the shortened rays of the points the aperture
  // filter dropped, and the cells they crossed (inside ms_rays). Not in the CSV row.
  size_t rays_uncertain = 0, uncertain_ray_cells = 0;
};

// Colours the vertices of a mesh of the sculptor (vertex_points from ExtractMesh or
// ExtractObservedMesh): each vertex the colour of its point, `grey` for a Steiner vertex or a
// point without a colour.
void ColorMeshVertices(const std::vector<PointId>& vertex_points,
                       const std::unordered_map<PointId, Rgb8>& point_colors, TriangleMesh* mesh,
                       uint8_t grey = 128);

// The mean distance between consecutive centres of the first `count` keyframes (0 with fewer
// than two): the keyframe spacing that s is measured from (SculptorOptions::scale).
double MeanKeyframeSpacing(const std::vector<SurfaceKeyframe>& keyframes, size_t count);

// The s that an IncrementalSculptor with these options measures on `keyframes` as its stream
// (SculptorOptions::scale: on the first init_keyframes, or the next ones when those do not move;
// options.scale when given); 0 when none moves. *spacing, when given: the mean keyframe spacing of
// the keyframes it was measured on (IncrementalSculptor::keyframe_spacing; 0 with options.scale).
double MeasureScale(const SculptorOptions& options, const std::vector<SurfaceKeyframe>& keyframes,
                    double* spacing = nullptr);

// The surface time per keyframe of a step: its ms_total over its keyframes (amortised when
// SculptorOptions::keyframes_per_step sculpts several at once).
double MsPerKeyframe(const KeyframeStats& stats);

std::string KeyframeStatsCsvHeader();
std::string KeyframeStatsCsvRow(const KeyframeStats& stats);

class IncrementalSculptor {
 public:
  explicit IncrementalSculptor(const SculptorOptions& options = {});
  ~IncrementalSculptor();

  // Takes the next keyframe. The first init_keyframes are buffered until s is known; returns
  // the stats of the keyframes this call processed (none while buffering).
  std::vector<KeyframeStats> AddKeyframe(const SurfaceKeyframe& keyframe);
  // Processes what is still buffered (a stream shorter than init_keyframes).
  std::vector<KeyframeStats> Finish();

  // δO, the closed surface of the paper (surface_closed.ply): triangles counter-clockwise seen
  // from the free space; with smoothing, at the smoothed vertex positions. vertex_points, when
  // given, receives the point id of each vertex (PointId::Invalid() for a Steiner vertex).
  TriangleMesh ExtractMesh(std::vector<PointId>* vertex_points = nullptr) const;
  // The observed part of δO (surface.ply, surface/observed_mesh.h with options.observed): an
  // oriented 2-manifold with boundary, its triangles a subset of ExtractMesh()'s, no Steiner
  // vertex. vertex_points as for ExtractMesh.
  TriangleMesh ExtractObservedMesh(std::vector<PointId>* vertex_points = nullptr,
                                   ObservedMeshStats* stats = nullptr) const;
  // The points inserted so far, in their order: those the §5.1 filters kept and whose conflict
  // zone did not meet O (the "points added" of KeyframeStats; not those merged into a vertex).
  std::vector<PointId> InsertedPoints() const;
  // The output position of the Delaunay vertex (DelaunayMesh index): smoothed, or its own.
  Eigen::Vector3d SurfacePosition(int vertex) const;
  // The smoothing that waited for a mesh to be taken (SmoothingOptions::every_keyframe off):
  // how often it ran, the vertices it recomputed and rejected moves, and its time, in total.
  struct DeferredSmoothing {
    size_t runs = 0, vertices = 0, rejected = 0;
    double seconds = 0.0;
  };
  DeferredSmoothing DeferredSmoothingStats() const;
  const DelaunayMesh& triangulation() const;
  double scale() const;  // s, 0 until known
  // The mean distance between the first keyframes' centres, which s is measured from (0 until
  // known, or when s was given).
  double keyframe_spacing() const;
  double ray_length_bound() const;  // r of §3.3 (max_ray_length_factor · s), 0 until known
  double ground_bound() const;      // b of the ground filter (SculptorOptions), 0 until known
  size_t NumProcessedKeyframes() const;

  // Invariants for tests and debugging: O ⊆ F, no infinite cell in O, the incremental counts
  // of O, F and δO equal recounts, T valid (expensive). Empty when all hold.
  std::string CheckInvariants(bool check_triangulation = true) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace omni
