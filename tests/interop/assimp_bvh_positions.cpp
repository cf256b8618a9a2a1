// Reads BVH files with Assimp's BVH importer and writes every node's world
// position in every frame, for tests/interop/bvh_readers_test.py.
//
//   gmr_assimp_bvh_positions MANIFEST
//
// MANIFEST: one file per line, "BVH<TAB>OUT.csv<TAB>FRAMES". Each CSV has the
// lines of `gmr positions` (frame,joint,x,y,z, frames from 0), except that the
// joint column is "#k": the k-th node of the hierarchy in file order (Assimp
// names End Sites "EndSite_<parent>"; the test maps k to gmr's name).
//
// Assimp has no animation evaluator in its API: this program applies the
// importer's keys as its documentation defines them (a node's transform is
// translation * rotation * scaling of its channel's key at that time, a
// channel with one key holds it, the world transform is the parent's times
// the node's) and nothing else. Keys sit at times 0, 1, ... (one per frame).
#include <assimp/cimport.h>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include <cstdio>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

namespace {

struct Reader {
  const aiScene* scene = nullptr;
  std::map<std::string, const aiNodeAnim*> channels;
  std::vector<const aiNode*> nodes;  // file order

  void collect(const aiNode* n) {
    nodes.push_back(n);
    for (unsigned i = 0; i < n->mNumChildren; ++i) collect(n->mChildren[i]);
  }

  aiMatrix4x4 local(const aiNode* n, unsigned frame) const {
    const auto it = channels.find(n->mName.C_Str());
    if (it == channels.end()) return n->mTransformation;
    const aiNodeAnim* c = it->second;
    const aiVector3D p = c->mPositionKeys[frame < c->mNumPositionKeys ? frame : 0].mValue;
    const aiQuaternion q = c->mRotationKeys[frame < c->mNumRotationKeys ? frame : 0].mValue;
    const aiVector3D s = c->mScalingKeys[frame < c->mNumScalingKeys ? frame : 0].mValue;
    return aiMatrix4x4(s, q, p);
  }

  void world(const aiNode* n, const aiMatrix4x4& parent, unsigned frame,
             std::map<const aiNode*, aiVector3D>& out) const {
    const aiMatrix4x4 w = parent * local(n, frame);
    out[n] = aiVector3D(w.a4, w.b4, w.c4);
    for (unsigned i = 0; i < n->mNumChildren; ++i) world(n->mChildren[i], w, frame, out);
  }
};

bool positions(const std::string& bvh, const std::string& out_path, unsigned frames) {
  const aiScene* scene = aiImportFile(bvh.c_str(), 0);
  if (scene == nullptr) {
    std::printf("assimp-bvh: %s: FAILED: %s\n", bvh.c_str(), aiGetErrorString());
    return false;
  }
  Reader r;
  r.scene = scene;
  if (scene->mNumAnimations > 0) {
    const aiAnimation* a = scene->mAnimations[0];
    for (unsigned i = 0; i < a->mNumChannels; ++i) r.channels[a->mChannels[i]->mNodeName.C_Str()] = a->mChannels[i];
  }
  r.collect(scene->mRootNode);
  std::ofstream out(out_path);
  out << "frame,joint,x,y,z\n";
  std::map<const aiNode*, aiVector3D> at;
  char line[160];
  for (unsigned f = 0; f < frames; ++f) {
    at.clear();
    r.world(scene->mRootNode, aiMatrix4x4(), f, at);
    for (std::size_t k = 0; k < r.nodes.size(); ++k) {
      const aiVector3D& p = at[r.nodes[k]];
      std::snprintf(line, sizeof line, "%u,#%zu,%.9g,%.9g,%.9g\n", f, k, p.x, p.y, p.z);
      out << line;
    }
  }
  aiReleaseImport(scene);
  if (!out) {
    std::printf("assimp-bvh: %s: FAILED: cannot write %s\n", bvh.c_str(), out_path.c_str());
    return false;
  }
  std::printf("assimp-bvh: %s: %u frames\n", bvh.c_str(), frames);
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s MANIFEST\n", argv[0]);
    return 2;
  }
  std::ifstream manifest(argv[1]);
  std::string line;
  int failed = 0;
  while (std::getline(manifest, line)) {
    std::istringstream fields(line);
    std::string bvh, out;
    unsigned frames = 0;
    if (!std::getline(fields, bvh, '\t') || !std::getline(fields, out, '\t') || !(fields >> frames)) continue;
    if (!positions(bvh, out, frames)) ++failed;
  }
  return failed == 0 ? 0 : 1;
}
