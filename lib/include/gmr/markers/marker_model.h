// A skeleton model for raw markers (the paper's S(G, R), section 5.1): the
// body parts and which markers ride on each (R), and the joints between them
// (the graph G), each with the rule that finds its centre. docs/markers.md
// describes the text format; builtin_marker_model("cmu41") is the model of
// the 41-marker Vicon set of the CMU database, with joints named like the
// bones of CMU's ASF skeletons (the joint "lfemur" is the end of the left
// femur: the knee).
//
//   gmr-marker-model 1
//   name example
//   part pelvis LFWT RFWT LBWT RBWT
//   part lthigh lhipjoint LTHI LKNE
//   joint root in pelvis at mean(LFWT, RFWT, LBWT, RBWT)
//   joint lhipjoint parent root in pelvis centre lthigh prior local(mean(LFWT, RFWT), LFWT, mean(LBWT, RBWT), 0.72,
//   0.1, -0.87)
//
// Parsing checks the model alone (names, references, order); which markers a
// file has is checked when the model is applied (gmr/markers/marker_solve.h).
#pragma once

#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "gmr/core/error.h"

namespace gmr {

// A point expression: where a prior or a marker-placed joint is, from the
// markers and the joints found before it, in one frame.
struct PointExpr {
  enum class Kind {
    kMarker,  // a marker's position
    kJoint,   // a joint found earlier
    kMean,    // mean of args
    kAlong,   // args[0] + length * unit(args[2] - args[1])
    kLocal,   // args[0] + a x + b y + c z, frame from args[0..2] (below)
  };
  Kind kind = Kind::kMarker;
  std::string name;             // kMarker, kJoint
  std::vector<PointExpr> args;  // kMean (>= 1), kAlong (3), kLocal (3)
  // kAlong: lengths[0]; kLocal: lengths[0..2] = a, b, c. A length is in
  // millimetres when `absolute`, else a multiple of |args[1] - args[0]|
  // (kLocal) or |args[2] - args[1]| (kAlong).
  // kLocal's frame: x = unit(args[1] - args[0]), z = unit(x cross (args[2] -
  // args[0])), y = z cross x.
  double lengths[3] = {0, 0, 0};
  bool absolute[3] = {false, false, false};
};

struct ModelPart {
  std::string name;
  // Markers (as named after a subject prefix is stripped) and joints; a
  // joint must be found before the part is fitted. Weights default to 1.
  std::vector<std::string> points;
  std::vector<double> weights;
  std::vector<bool> point_is_joint;  // filled by the parser
  int line = 0;                      // in the model text, for messages
};

struct ModelJoint {
  enum class Rule {
    kAt,      // at EXPR: fixed in its part where EXPR is on average
    kCentre,  // centre CHILD [hinge] prior EXPR: the point of its part that CHILD's markers turn about
  };
  std::string name;
  int parent = -1;  // index into MarkerModel::joints; -1: a root of the model's tree
  int part = -1;    // the part the bone parent -> joint lies in (the joint is fixed in it)
  Rule rule = Rule::kAt;
  int child_part = -1;  // kCentre
  // kCentre: a hinge (`centre CHILD hinge prior ...`) takes at most one
  // direction from the take, the one flexion sweeps the child's markers
  // along most; the axis and the direction along the child bone (which a
  // flexion of less than 90 degrees barely moves them along) take the
  // prior's coordinates.
  bool hinge = false;
  PointExpr where;  // kAt: the position; kCentre: the prior
  // `split END FRACTION`: once found, the joint slides along the line from
  // its parent so that the bone parent -> joint is FRACTION of the chain's
  // length parent -> joint -> END (END: a joint further down the tree; both
  // bones' median lengths over the take; repeated while moving the joint
  // moves END, until it holds). It fixes the coordinate along the
  // bone that neither a lateral marker nor a short flexion does, from the
  // limb's proportions. -1: no split.
  int split = -1;
  std::string split_name;
  double split_fraction = 0;
  int line = 0;
};

struct MarkerModel {
  std::string name;
  std::vector<ModelPart> parts;
  std::vector<ModelJoint> joints;  // every parent before its children
  // A marker whose distance to its part's fit exceeds this (millimetres) is
  // left out of that frame's fit while 3 or more points remain.
  double outlier_mm = 40;
  // kCentre: a direction the motion moves the child's markers along by
  // less than this RMS distance (millimetres), or by less than
  // min_relative_spread of the best direction, takes the prior's coordinate.
  double min_spread_mm = 15;
  double min_relative_spread = 0.2;

  int find_part(std::string_view name) const;
  int find_joint(std::string_view name) const;
  // Every marker name the model uses, each once, in order of first use.
  std::vector<std::string> marker_names() const;
};

// Parses the text format. `label` names the source in errors
// ("label:line:column: what"). A text whose only statement is
// `builtin NAME` is that built-in model.
Result<MarkerModel> parse_marker_model(std::string_view text, std::string_view label);
Result<MarkerModel> read_marker_model(const std::filesystem::path& path);
// The built-in models by name ("cmu41"), as text and parsed.
std::vector<std::string> builtin_marker_model_names();
Result<std::string> builtin_marker_model_text(std::string_view name);
Result<MarkerModel> builtin_marker_model(std::string_view name);
// A built-in name, else a model file's path.
Result<MarkerModel> find_marker_model(std::string_view name_or_path);

// A marker file's name without a Vicon subject prefix: "TakeoMonday:LKNE" ->
// "LKNE" (the text after the last ':').
std::string_view strip_subject_prefix(std::string_view marker_name);

}  // namespace gmr
