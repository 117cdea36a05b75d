// The table of demo scenes (scene_demos.h).
#include "scenes/scene_demos.h"

#include <stdexcept>

namespace meshsweeper::scenes {

const std::vector<std::string>& sceneNames() {
  static const std::vector<std::string> names = {"hausdorff", "particle", "cloth"};
  return names;
}

std::string runScene(const std::string& name, const std::string& out_dir, std::FILE* log) {
  if (name == "hausdorff") return hausdorffScene(out_dir, log);
  if (name == "particle") return particleScene(out_dir, log);
  if (name == "cloth") return clothScene(out_dir, log);
  throw std::invalid_argument("unknown scene '" + name + "' (hausdorff, particle, cloth, all)");
}

}  // namespace meshsweeper::scenes
