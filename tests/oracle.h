#pragma once
// Shared pieces of the oracle tests (Catch2): the real meshes, failure counting, and
// full-precision printing of numbers and points for failure messages.
#include "core/mesh_io.h"
#include "scenes/procedural.h"

#include <catch2/catch.hpp>

#include <filesystem>
#include <map>
#include <memory>
#include <sstream>
#include <string>

namespace meshsweeper::oracle {

// x with 17 significant digits (enough to round-trip a double).
inline std::string num(double x) {
  std::ostringstream out;
  out.precision(17);
  out << x;
  return out.str();
}

inline std::string text(const Vec3& p) { return "(" + num(p.x()) + ", " + num(p.y()) + ", " + num(p.z()) + ")"; }

// Counts the failures of one kind of check; reports the first few in full (with the INFO
// context), then a total, so a broken invariant does not print thousands of lines.
class Failures {
 public:
  explicit Failures(std::string what) : what_(std::move(what)) {}
  Failures(const Failures&) = delete;
  Failures& operator=(const Failures&) = delete;
  template <class F>
  void check(bool ok, F&& message) {
    ++checks_;
    if (ok) return;
    if (++count_ <= kShown) FAIL_CHECK(what_ << ": " << message());
  }
  ~Failures() {
    if (count_ > kShown) FAIL_CHECK(what_ << ": " << count_ << " failures in all (first " << kShown << " shown)");
  }
  size_t checks() const { return checks_; }
  size_t count() const { return count_; }

 private:
  static constexpr size_t kShown = 4;
  std::string what_;
  size_t count_ = 0;
  size_t checks_ = 0;
};

// A real mesh from data/meshes, read once per test binary. A missing file is a failure (the
// test command extracts the meshes first) and gives nullptr.
inline const Mesh* realMesh(const std::string& name) {
  static std::map<std::string, std::unique_ptr<Mesh>> cache;
  auto it = cache.find(name);
  if (it != cache.end()) return it->second.get();
  const std::string path = scenes::meshPath(name);
  std::unique_ptr<Mesh> mesh;
  if (!std::filesystem::exists(path)) {
    FAIL_CHECK("missing real mesh " << path << " (run scripts/fetch_data.sh)");
  } else {
    mesh = std::make_unique<Mesh>(readMesh(path));
    mesh->name = name;
  }
  return cache.emplace(name, std::move(mesh)).first->second.get();
}

}  // namespace meshsweeper::oracle
