// What the importers of io/import.h share: view ids from file names, copies, pair.txt ranking,
// depth ranges, the checks every importer makes. Private to src/io.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "unsup_mvs/io/mvs_folder.h"

namespace umvs::import_detail {

// The last run of digits in a file name's stem ("templeR0013" -> 13); -1 when there is none.
int id_from_name(const std::string& name);
// Copies a file's bytes to `to`, written atomically.
void copy_atomically(const std::string& from, const std::string& to);

struct ImportedView {
  int id = 0;
  MvsCam cam;
};

// pair.txt: every view against all others, ranked by the view-selection score on `points`.
// Sources whose centre lies min_baseline..max_baseline from the reference's rank before the others
// (max_baseline 0 = no upper limit): on hand-held video the best-scoring neighbours are often the
// next frames, a few centimetres away, too little parallax for the planes.
void write_pairs(const std::string& path, const std::vector<ImportedView>& views,
                 const std::vector<std::vector<Eigen::Vector3d>>& points_per_view, int num_sources,
                 double min_baseline = 0.0, double max_baseline = 0.0);

// The cam file's range [zmin, zmax] widened by `margin` of its length each side (at least 5 % of
// zmax: a flat scene still needs a range to sweep); throws naming `what` for an impossible one.
void set_depth_range(MvsCam& cam, double zmin, double zmax, double margin, int depth_num, const std::string& what);

// What every importer refuses before reading anything.
void check_import_folders(const std::string& data_dir, const std::string& out_dir, int depth_num, int num_sources);

// The whitespace-separated numbers of a text; names `where` and the token that is not one.
std::vector<double> numbers_in(const std::string& text, const std::string& where);

// The depth image of a colour frame: the same stem in depth/, whatever the format (RGB-D
// sequences pair colour JPEGs or PNGs with 16-bit PNG or PGM depth).
std::string depth_image_for(const std::string& depth_dir, const std::string& color_path);

}  // namespace umvs::import_detail
