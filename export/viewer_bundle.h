#pragma once
// The offline web viewer of a reconstruction folder (`omnisculpt view OUT`): OUT/viewer/ gets
// the page (index.html, viewer.js, viewer.css), the three.js scripts (lib/) and the data
// (data/*.js), each data file a classic script that assigns a global, so the page works when
// opened from the file system (file://: no fetch, no ES modules) and fetches nothing.
//
// Data: data/scene.js (window.OMNI_SCENE: keyframe poses from poses.tum, every rig camera's
// pose per keyframe from sparse/images.txt and its field of view from sparse/cameras.txt, the
// loop closures of reconstruct.json, stats/keyframes.csv as text, the list of snapshots),
// data/surface.js (the .glb of export/gltf.h, base64: surface.ply and the SfM points of
// sparse/points3D.txt, or points.ply, ordered by the first keyframe that observed them) and one
// data/snapshot_<keyframe>.js per snapshot (a .glb): snapshots/observed_<keyframe>.ply as it
// is, the observed surface of that moment coloured as surface.ply; for a reconstruction folder
// without it (written before those files existed), snapshots/surface_<keyframe>.ply, the closed
// δO of that moment, filtered and coloured by the final SfM points (see ViewerOptions).

#include <filesystem>
#include <string>

namespace omni {

struct ViewerOptions {
  // The page and the three.js scripts: index.html, viewer.js, viewer.css and lib/ (the build
  // puts them beside the executable, in viewer_assets/).
  std::filesystem::path assets;
  // A snapshot vertex without a colour (the closed δO of a folder without observed snapshots)
  // takes the colour of the nearest final SfM point within this distance (map units), grey
  // otherwise.
  double snapshot_color_radius = 0.5;
  // Such a closed snapshot (with the caps and the Steiner vertices) loses its triangles with a
  // vertex that has no final SfM point within snapshot_color_radius, so that it looks like the
  // observed surface it grows into. Where the map moved after the snapshot (a non-central
  // run's early keyframes) that leaves out observed triangles too; the observed snapshots need
  // no such filter.
  bool snapshot_without_steiner = true;

  std::string Check() const;
};

struct ViewerSummary {
  std::filesystem::path index;  // OUT/viewer/index.html
  size_t keyframes = 0, cameras = 0, points = 0, triangles = 0, snapshots = 0, loops = 0;
  size_t bytes = 0;  // of OUT/viewer/data/
};

// Writes `reconstruction`/viewer/ (built in viewer.incomplete/ and renamed when whole; a
// previous viewer/ is replaced only if it holds data/scene.js). Throws InputError naming the
// file when surface.ply or poses.tum is missing or malformed, when a viewer/ of other files is
// in the way, or when the assets are missing.
ViewerSummary WriteViewer(const std::filesystem::path& reconstruction,
                          const ViewerOptions& options);

}  // namespace omni
