// Tests for core/mesh_io: readMesh on small hand-written files of every format (order kept, fan
// triangulation, valid oddities) and on every kind of bad input; readPoints; writeOff.
#include "core/brute_force.h"
#include "core/mesh_io.h"

#include <catch2/catch.hpp>

#include <fcntl.h>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <locale>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

using meshsweeper::Mesh;
using meshsweeper::MeshError;
using meshsweeper::Triangle;
using meshsweeper::Vec3;
using Catch::Matchers::Contains;
using Catch::Matchers::EndsWith;
using Catch::Matchers::StartsWith;

namespace {

// A fresh directory under the system temp folder, removed with everything in it.
class TempDir {
 public:
  TempDir() {
    std::string pattern = (std::filesystem::temp_directory_path() / "meshsweeper_io_XXXXXX").string();
    if (mkdtemp(pattern.data()) == nullptr) throw std::runtime_error("mkdtemp failed");
    path_ = pattern;
  }
  ~TempDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;

  std::string file(const std::string& name) const { return (path_ / name).string(); }

  // Writes bytes with fwrite and returns the file's path.
  std::string write(const std::string& name, const std::string& bytes) const {
    const std::string path = file(name);
    std::FILE* f = std::fopen(path.c_str(), "wb");
    REQUIRE(f != nullptr);
    REQUIRE(std::fwrite(bytes.data(), 1, bytes.size(), f) == bytes.size());
    std::fclose(f);
    return path;
  }

 private:
  std::filesystem::path path_;
};

// Little builders for binary files.
void putU8(std::string& s, unsigned v) { s += static_cast<char>(v & 0xffu); }
void putU32(std::string& s, std::uint32_t v, bool big_endian = false) {
  for (int b = 0; b < 4; ++b) putU8(s, v >> (8 * (big_endian ? 3 - b : b)));
}
void putF32(std::string& s, float v, bool big_endian = false) {
  std::uint32_t bits;
  std::memcpy(&bits, &v, 4);
  putU32(s, bits, big_endian);
}
void putF64(std::string& s, double v, bool big_endian = false) {
  std::uint64_t bits;
  std::memcpy(&bits, &v, 8);
  for (int b = 0; b < 8; ++b) putU8(s, static_cast<unsigned>(bits >> (8 * (big_endian ? 7 - b : b))));
}

// A binary STL: 80-byte header, count, then per triangle a normal, 3 corners and 2 spare bytes.
std::string binaryStl(const std::string& header, const std::vector<std::array<Vec3, 3>>& triangles,
                      std::uint32_t declared) {
  std::string s = header;
  s.resize(80, ' ');
  putU32(s, declared);
  for (const auto& t : triangles) {
    for (int k = 0; k < 3; ++k) putF32(s, 0.0f);
    for (const Vec3& p : t)
      for (int k = 0; k < 3; ++k) putF32(s, static_cast<float>(p[k]));
    putU8(s, 0);
    putU8(s, 0);
  }
  return s;
}

// The message of the MeshError that readMesh throws, or "(no error)". Any other exception
// escapes and fails the test.
std::string readError(const std::string& path) {
  try {
    meshsweeper::readMesh(path);
  } catch (const MeshError& e) {
    return e.what();
  }
  return "(no error)";
}

std::string pointsError(const std::string& path) {
  try {
    meshsweeper::readPoints(path);
  } catch (const MeshError& e) {
    return e.what();
  }
  return "(no error)";
}

// The unit square split into two triangles, and a pentagon, as positions used by several files:
//
//   3 ---- 2        fan of quad 0 1 2 3:        (0,1,2) (0,2,3)
//   |      |        fan of pentagon 0 1 4 5 6:  (0,1,4) (0,4,5) (0,5,6)
//   0 ---- 1
const std::vector<Vec3> kSquare = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};

// A PLY number type by name, for typedPly.
struct PlyTestType {
  int bytes;
  bool integer;
  bool is_signed;
};
PlyTestType plyTestType(const std::string& name) {
  if (name == "char" || name == "int8") return {1, true, true};
  if (name == "uchar" || name == "uint8") return {1, true, false};
  if (name == "short" || name == "int16") return {2, true, true};
  if (name == "ushort" || name == "uint16") return {2, true, false};
  if (name == "int" || name == "int32") return {4, true, true};
  if (name == "uint" || name == "uint32") return {4, true, false};
  if (name == "float" || name == "float32") return {4, false, true};
  if (name == "double" || name == "float64") return {8, false, true};
  throw std::invalid_argument("no PLY type " + name);
}

enum class PlyTestFormat { kAscii, kLittleEndian, kBigEndian };

// Appends a PLY value of the named type: in ASCII its text and a space, in binary its bytes in
// the format's byte order (an integer type takes the value's two's complement bits).
void putPly(std::string& s, PlyTestFormat format, const std::string& type_name, double value) {
  const PlyTestType type = plyTestType(type_name);
  if (format == PlyTestFormat::kAscii) {
    std::ostringstream text;
    text.imbue(std::locale::classic());
    text.precision(17);
    text << value << ' ';
    s += text.str();
    return;
  }
  std::uint64_t bits;
  if (type.integer) {
    bits = static_cast<std::uint64_t>(static_cast<std::int64_t>(value));
  } else if (type.bytes == 4) {
    const float f = static_cast<float>(value);
    std::uint32_t b32;
    std::memcpy(&b32, &f, 4);
    bits = b32;
  } else {
    std::memcpy(&bits, &value, 8);
  }
  const bool big = format == PlyTestFormat::kBigEndian;
  for (int b = 0; b < type.bytes; ++b) putU8(s, static_cast<unsigned>(bits >> (8 * (big ? type.bytes - 1 - b : b))));
}

// The values of the extra vertex properties after z and face properties after the list.
const std::pair<const char*, double> kVertexExtras[] = {{"float", 0.5}, {"uchar", 1}, {"uchar", 2}, {"uchar", 255}};
const std::pair<const char*, double> kFaceExtras[] = {{"int", -7}, {"uchar", 4}, {"uchar", 5}, {"uchar", 6}};

// A PLY file of a mesh with the given types for the vertex coordinates, the face index items and
// the face list's count. With `extras`, other properties sit around the ones read so that a wrong
// offset shows: an element before the vertices (a list of char with a ushort count), a vertex
// property between x and y and others after z (colours, which CGAL reads), face properties
// before and after the list (colours too), and an element after the faces (a ushort list).
// `line_end` ends the header's lines (and an ASCII body's).
std::string typedPly(PlyTestFormat format, const std::string& coordinate, const std::string& index,
                     const std::string& count, const std::vector<Vec3>& positions,
                     const std::vector<std::vector<std::int64_t>>& faces, bool extras = true,
                     const std::string& index_name = "vertex_indices", const std::string& line_end = "\n") {
  const char* format_name = format == PlyTestFormat::kAscii          ? "ascii"
                            : format == PlyTestFormat::kLittleEndian ? "binary_little_endian"
                                                                     : "binary_big_endian";
  std::string s = "ply" + line_end + "format " + format_name + " 1.0" + line_end + "comment typedPly" + line_end;
  if (extras) s += "element camera 1" + line_end + "property double focal" + line_end +
                   "property list ushort char tags" + line_end;
  s += "element vertex " + std::to_string(positions.size()) + line_end + "property " + coordinate + " x" + line_end;
  if (extras) s += "property short id" + line_end;
  s += "property " + coordinate + " y" + line_end + "property " + coordinate + " z" + line_end;
  if (extras) s += "property float confidence" + line_end + "property uchar red" + line_end +
                   "property uchar green" + line_end + "property uchar blue" + line_end;
  s += "element face " + std::to_string(faces.size()) + line_end;
  if (extras) s += "property uchar kind" + line_end;
  s += "property list " + count + " " + index + " " + index_name + line_end;
  if (extras) s += "property int flags" + line_end + "property uchar red" + line_end + "property uchar green" +
                   line_end + "property uchar blue" + line_end + "element edge 2" + line_end +
                   "property list uchar ushort corners" + line_end + "property char weight" + line_end;
  s += "end_header" + line_end;
  const auto item_end = [&] {
    if (format == PlyTestFormat::kAscii) s += line_end;
  };
  if (extras) {
    putPly(s, format, "double", 35.5);
    putPly(s, format, "ushort", 3);
    for (double tag : {-1.0, 2.0, -128.0}) putPly(s, format, "char", tag);
    item_end();
  }
  for (std::size_t v = 0; v < positions.size(); ++v) {
    putPly(s, format, coordinate, positions[v].x());
    if (extras) putPly(s, format, "short", -2.0 - static_cast<double>(v));
    putPly(s, format, coordinate, positions[v].y());
    putPly(s, format, coordinate, positions[v].z());
    if (extras)
      for (const auto& [type, value] : kVertexExtras) putPly(s, format, type, value);
    item_end();
  }
  for (const auto& face : faces) {
    if (extras) putPly(s, format, "uchar", 9);
    putPly(s, format, count, static_cast<double>(face.size()));
    for (std::int64_t corner : face) putPly(s, format, index, static_cast<double>(corner));
    if (extras)
      for (const auto& [type, value] : kFaceExtras) putPly(s, format, type, value);
    item_end();
  }
  if (extras) {
    for (int edge = 0; edge < 2; ++edge) {
      putPly(s, format, "uchar", 2);
      putPly(s, format, "ushort", 1);
      putPly(s, format, "ushort", static_cast<double>(positions.size() - 1));
      putPly(s, format, "char", -3);
      item_end();
    }
  }
  return s;
}

// Positions and faces for the typed PLY tests: a square, a quad on it, a triangle between the
// coordinate type's extremes (vertices 4 and 5) and the last vertex, and a pentagon through the
// last vertex; `count` vertices, so that 2-byte indices reach past 255.
struct TypedMesh {
  std::vector<Vec3> positions;
  std::vector<std::vector<std::int64_t>> faces;
  std::vector<Triangle> triangles;  // the fans, in face order
};
TypedMesh typedMesh(const std::string& coordinate, std::size_t count) {
  const PlyTestType type = plyTestType(coordinate);
  const int bits = 8 * type.bytes;
  const double lo = !type.integer ? -1000.0 : type.is_signed ? -std::ldexp(1.0, bits - 1) : 0.0;
  const double hi = !type.integer ? 1000.0 : type.is_signed ? std::ldexp(1.0, bits - 1) - 1 : std::ldexp(1.0, bits) - 1;
  TypedMesh mesh;
  mesh.positions = {{0, 0, 0}, {2, 0, 0}, {2, 2, 0}, {0, 2, 0}, {lo, hi, 0}, {hi, lo, 1}};
  for (std::size_t k = 6; k + 1 < count; ++k)
    mesh.positions.emplace_back(static_cast<double>(k % 50), static_cast<double>(k / 50), 5);
  mesh.positions.emplace_back(3, 1, 0);
  const auto last = static_cast<std::int64_t>(count - 1);
  mesh.faces = {{0, 1, 2, 3}, {4, 5, last}, {0, 1, last, 2, 3}};
  const auto l = static_cast<meshsweeper::VertexIndex>(last);
  mesh.triangles = {{0, 1, 2}, {0, 2, 3}, {4, 5, l}, {0, 1, l}, {0, l, 2}, {0, 2, 3}};
  return mesh;
}

const PlyTestFormat kPlyFormats[] = {PlyTestFormat::kAscii, PlyTestFormat::kLittleEndian, PlyTestFormat::kBigEndian};
const char* plyFormatName(PlyTestFormat format) {
  return format == PlyTestFormat::kAscii ? "ascii" : format == PlyTestFormat::kLittleEndian ? "binary LE" : "binary BE";
}

}  // namespace

TEST_CASE("ASCII OFF keeps file order and fan-triangulates polygons in face order", "[mesh_io]") {
  TempDir dir;
  const std::string path = dir.write("shapes.off",
                                     "# a comment before the header\n"
                                     "OFF\n"
                                     "7 3 0\n"
                                     "0 0 0\n"
                                     "1 0 0   # trailing comment\n"
                                     "1 1 0\n"
                                     "\n"
                                     "# whole-line comment between vertices\n"
                                     "0 1 0\n"
                                     "2 0.5 0\n"
                                     "2.5 1.5 -1e-3\n"
                                     "1.5 2 0.25\n"
                                     "4 0 1 2 3\n"
                                     "5 0 1 4 5 6\n"
                                     "3 6 5 4\n");
  const Mesh mesh = meshsweeper::readMesh(path);
  CHECK(mesh.name == path);
  REQUIRE(mesh.positions.size() == 7);
  for (int v = 0; v < 4; ++v) CHECK(mesh.positions[v] == kSquare[v]);
  CHECK(mesh.positions[4] == Vec3(2, 0.5, 0));
  CHECK(mesh.positions[5] == Vec3(2.5, 1.5, -1e-3));
  CHECK(mesh.positions[6] == Vec3(1.5, 2, 0.25));
  const std::vector<Triangle> expected = {{0, 1, 2}, {0, 2, 3},              // quad
                                          {0, 1, 4}, {0, 4, 5}, {0, 5, 6},  // pentagon
                                          {6, 5, 4}};                        // triangle
  CHECK(mesh.triangles == expected);
}

TEST_CASE("OFF header variants: counts on the keyword line, CRLF, COFF colours", "[mesh_io]") {
  TempDir dir;
  const std::vector<Triangle> expected = {{0, 1, 2}, {0, 2, 3}};
  SECTION("counts on the keyword line, CRLF line ends") {
    const Mesh mesh = meshsweeper::readMesh(
        dir.write("crlf.off", "OFF 4 1 0\r\n0 0 0\r\n1 0 0\r\n1 1 0\r\n0 1 0\r\n4 0 1 2 3\r\n"));
    CHECK(mesh.positions == kSquare);
    CHECK(mesh.triangles == expected);
  }
  SECTION("COFF with vertex and face colours, no newline at the end") {
    const Mesh mesh = meshsweeper::readMesh(dir.write(
        "colour.off", "COFF\n4 1 0\n0 0 0 255 0 0 255\n1 0 0 0 255 0 255\n1 1 0 0 0 255 255\n"
                      "0 1 0 9 9 9 255\n4 0 1 2 3 10 20 30"));
    CHECK(mesh.positions == kSquare);
    CHECK(mesh.triangles == expected);
  }
  SECTION("comments: on the keyword line, own lines, after the counts; not between the counts") {
    const std::string body = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";
    for (const std::string header : {"OFF # keyword\n4 1 0\n", "OFF\n# own line\n4 1 0 # counts\n", "OFF\n4\n1 0\n"}) {
      INFO(header);
      CHECK(meshsweeper::readMesh(dir.write("comment.off", header + body)).triangles == expected);
    }
    CHECK_THAT(readError(dir.write("between.off", "OFF\n4 # vertices\n1 0\n" + body)),
               Contains("between.off: the OFF header has a comment between its vertex and face counts"));
  }
  SECTION("colours CGAL cannot read safely are refused by line; its keyword variants checked") {
    // Found by review: a negative or huge colour-map index crashed CGAL's reader, a colour of 2
    // numbers made it read past them; NOFF or 4OFF vertices short of numbers got a vague message.
    const std::string square = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n";
    CHECK_THAT(readError(dir.write("neg.off", "COFF\n4 1 0\n" + square + "4 0 1 2 3 -100000000\n")),
               Contains("line 7: face 0: colour-map index '-100000000'"));
    CHECK_THAT(readError(dir.write("huge.off", "COFF\n4 1 0\n" + square + "4 0 1 2 3 1e10\n")),
               Contains("colour-map index '1e10'"));
    CHECK_THAT(readError(dir.write("vneg.off", "COFF\n4 1 0\n0 0 0 -5\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")),
               Contains("line 3: vertex 0: colour-map index '-5'"));
    CHECK_THAT(readError(dir.write("two.off", "COFF\n4 1 0\n" + square + "4 0 1 2 3 10 20\n")),
               Contains("a colour needs 1, 3 or 4 numbers, not 2"));
    CHECK(meshsweeper::readMesh(dir.write("index.off", "COFF\n4 1 0\n0 0 0 7\n1 0 0 200\n1 1 0 0.5 0.5 0.5\n"
                                                       "0 1 0 9 9 9 1\n4 0 1 2 3 5\n"))
              .triangles == expected);
    CHECK(meshsweeper::readMesh(dir.write("uncoloured.off", "COFF\n4 1 0\n" + square + "4 0 1 2 3\n")).triangles ==
          expected);
    // Found under ASan: once a vertex (face) has a colour, CGAL reads one for every later one,
    // past the end of a line without.
    CHECK_THAT(readError(dir.write("some.off", "COFF\n4 1 0\n0 0 0 7\n1 0 0 200\n1 1 0\n0 1 0\n4 0 1 2 3\n")),
               Contains("line 5: vertex 2: no colour, but an earlier vertex has one (colour every vertex or none)"));
    CHECK_THAT(readError(dir.write("some_faces.off", "COFF\n4 2 0\n" + square + "3 0 1 2 1 2 3\n3 0 2 3\n")),
               Contains("line 8: face 1: no colour, but an earlier face has one"));
    // Found by review: CGAL read texture coordinates at uninitialised indices without colours;
    // it is given the keyword without ST, C and N, and the positions alone count.
    const Mesh textured = meshsweeper::readMesh(
        dir.write("st.off", "STOFF\n4 1 0\n0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n0 1 0 0 1\n4 0 1 2 3\n"));
    CHECK(textured.positions == kSquare);
    CHECK(textured.triangles == expected);
    const Mesh all = meshsweeper::readMesh(dir.write(
        "stcn.off", "STCNOFF 4 1 0\n0 0 0 0 0 1 5 0 0\n1 0 0 0 0 1 5 1 0\n1 1 0 0 0 1 1 0 0 1 1\n"
                    "0 1 0 0 0 1 0.5 0.5 0.5 0 1\n4 0 1 2 3 0 0 255\n"));
    CHECK(all.positions == kSquare);
    CHECK(all.triangles == expected);
    CHECK(meshsweeper::readMesh(dir.write("st4.off", "ST4OFF\n4 1 0\n0 0 0 2 0 0 1\n2 0 0 2 1 0 1\n"
                                                     "2 2 0 2 1 1 1\n0 2 0 2 0 1 1\n4 0 1 2 3\n"))
              .positions == kSquare);
    CHECK(meshsweeper::readMesh(dir.write("later.off", "COFF\n4 2 0\n" + square + "3 0 1 2\n3 0 2 3 4\n"))
              .triangles.size() == 2);
    CHECK_THAT(readError(dir.write("noff.off", "NOFF\n4 1 0\n" + square + "4 0 1 2 3\n")),
               Contains("line 3: vertex 0 has 3 numbers, but a vertex of NOFF needs 6"));
    const Mesh normals = meshsweeper::readMesh(dir.write(
        "normals.off", "NOFF\n4 1 0\n0 0 0 0 0 1\n1 0 0 0 0 1\n1 1 0 0 0 1\n0 1 0 0 0 1\n4 0 1 2 3\n"));
    CHECK(normals.positions == kSquare);
    CHECK_THAT(readError(dir.write("four.off", "4OFF\n4 1 0\n" + square + "4 0 1 2 3\n")),
               Contains("a vertex of 4OFF needs 4"));
    CHECK_THAT(readError(dir.write("glued.off", "OFF#c\n4 1 0\n" + square + "4 0 1 2 3\n")),
               Contains("a comment right after the 'OFF' keyword"));
    CHECK_THAT(readError(dir.write("edges.off", "OFF\n4 1 99999999999\n" + square + "4 0 1 2 3\n")),
               Contains("edge count 99999999999 is too large"));
    // Found by fuzzing: CGAL doubles the edge count in an int (2^30 overflowed), and estimates
    // 2.1 (vertices + faces) half-edges in an int (a sparse file of 8 GB stands for the body).
    CHECK_THAT(readError(dir.write("edges30.off", "OFF\n4 1 1073741824\n" + square + "4 0 1 2 3\n")),
               Contains("edge count 1073741824 is too large"));
    CHECK(meshsweeper::readMesh(dir.write("edges29.off", "OFF\n4 1 1073741823\n" + square + "4 0 1 2 3\n"))
              .positions == kSquare);
    const std::string huge = dir.write("huge.off", "OFF\n600000000 500000000 0\n0 0 0\n");
    std::error_code sparse;
    std::filesystem::resize_file(huge, 8000000000ull, sparse);
    if (!sparse)
      CHECK_THAT(readError(huge), Contains("600000000 vertices and 500000000 faces: more than 1000000000 in all"));
    // Found by review: CGAL read what follows the counts on their line as vertex 0.
    CHECK_THAT(readError(dir.write("after.off", "OFF\n3 1 0 9 9 9\n0 0 0\n1 0 0\n3 0 1 2\n3 0 1 2\n")),
               Contains("the OFF header line has more after its counts: '9' (CGAL would read it as vertex 0"));
    CHECK_THAT(readError(dir.write("half.off", "OFF 3 1 0.5 7 7\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")),
               Contains("more after its counts: '.5'"));
    CHECK(meshsweeper::readMesh(dir.write("note.off", "OFF\n4 1 0 \t# counts\r\n" + square + "4 0 1 2 3\n")).positions ==
          kSquare);
    // CGAL refuses a digit as the keyword's second character; it is given '4OFF' for these.
    for (const char* keyword : {"C4OFF", "N4OFF"}) {
      INFO(keyword);
      const std::string extra = keyword[0] == 'C' ? " 1 0 0" : " 0 0 1 1";
      std::string text = std::string(keyword) + "\n4 1 0\n";
      for (const char* v : {"0 0 0 1", "1 0 0 1", "1 1 0 1", "0 1 0 1"}) text += v + extra + "\n";
      CHECK(meshsweeper::readMesh(dir.write("c4.off", text + "4 0 1 2 3\n")).positions == kSquare);
    }
    // A colour word CGAL would read part of ('-5' of '-5x') is not a colour here, and CGAL no
    // longer reads colours at all.
    CHECK(meshsweeper::readMesh(dir.write("suffix.off", "COFF\n4 1 0\n0 0 0 -100000x\n1 0 0 1\n1 1 0 1\n"
                                                        "0 1 0 1\n4 0 1 2 3 -100000x\n"))
              .positions == kSquare);
  }
  SECTION("upper-case extension") {
    const Mesh mesh =
        meshsweeper::readMesh(dir.write("UPPER.OFF", "OFF\n3 1 0\n0 0 0\n1 0 0\n1 1 0\n3 0 1 2\n"));
    CHECK(mesh.triangles.size() == 1);
  }
}

TEST_CASE("degenerate triangles, duplicate and isolated vertices are valid input", "[mesh_io]") {
  TempDir dir;
  // Vertex 4 duplicates vertex 1; vertex 5 is used by no face; face 2 repeats an index;
  // face 3 has collinear corners; face 4 has three coincident corners (1, 4 and 4).
  const Mesh mesh = meshsweeper::readMesh(dir.write("odd.off",
                                                    "OFF\n7 5 0\n"
                                                    "0 0 0\n1 0 0\n0 1 0\n2 0 0\n"
                                                    "1 0 0\n"
                                                    "5 5 5\n"
                                                    "3 0 0\n"
                                                    "3 0 1 2\n"
                                                    "3 2 4 0\n"
                                                    "3 0 0 1\n"
                                                    "3 0 1 3\n"
                                                    "3 1 4 4\n"));
  CHECK(mesh.positions.size() == 7);
  CHECK(mesh.positions[4] == mesh.positions[1]);
  CHECK(mesh.positions[5] == Vec3(5, 5, 5));
  CHECK(mesh.positions[6] == Vec3(3, 0, 0));
  const std::vector<Triangle> expected = {{0, 1, 2}, {2, 4, 0}, {0, 0, 1}, {0, 1, 3}, {1, 4, 4}};
  CHECK(mesh.triangles == expected);
}

TEST_CASE("OBJ: order kept, v/vt/vn faces, negative indices, ignored statements", "[mesh_io]") {
  TempDir dir;
  const Mesh mesh = meshsweeper::readMesh(dir.write("square.obj",
                                                    "# exported by hand\n"
                                                    "mtllib none.mtl\n"
                                                    "o square\n"
                                                    "v 0 0 0\n"
                                                    "v 1 0 0\n"
                                                    "v 1 1 0\n"
                                                    "v 0 1 0\n"
                                                    "vt 0 0\nvn 0 0 1\n"
                                                    "g group\ns off\nusemtl x\n"
                                                    "l 1 2\n  l 2 3 4\n"  // line elements: not faces
                                                    "f 1/1/1 2/1/1 3/1/1 4/1/1\n"
                                                    "f -1 -2 -4\n"
                                                    "f 1//1 3//1 4//1\n"));
  CHECK(mesh.positions == kSquare);
  const std::vector<Triangle> expected = {{0, 1, 2}, {0, 2, 3}, {3, 2, 0}, {0, 2, 3}};
  CHECK(mesh.triangles == expected);
  // A bare 'l' as the last line, with no line break after it (found by review).
  CHECK(meshsweeper::readMesh(dir.write("last_l.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nl")).triangles.size() == 1);
  // A corner's '/t/n' part longer than 256 characters (found by review: CGAL skips 256 after
  // the index and read the rest, here '4', as a further corner, making a quad).
  const Mesh long_corner = meshsweeper::readMesh(dir.write("long.obj",
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nf 1/" + std::string(255, '0') + "4/1 2 3\n"));
  const std::vector<Triangle> one = {{0, 1, 2}};
  CHECK(long_corner.triangles == one);
  // Vertex coordinates are whole numbers (found by review: CGAL's stream read '1-5' as 1 and
  // -5, '3abc' as 3); '#' starts a comment anywhere (CGAL read 'f 1 2#x 3' as a triangle).
  const std::string rest = "v 0 1 0\nf 1 2 3\n";
  CHECK_THAT(readError(dir.write("minus.obj", "v 0 0 0\nv 1-5 0 0\n" + rest)), Contains("line 2: vertex 1: '1-5'"));
  CHECK_THAT(readError(dir.write("dots.obj", "v 0 0 0\nv 1.5.7 0 0\n" + rest)), Contains("'1.5.7'"));
  CHECK_THAT(readError(dir.write("abc.obj", "v 1 2 3abc\nv 1 0 0\n" + rest)), Contains("line 1: vertex 0: '3abc'"));
  CHECK_THAT(readError(dir.write("two.obj", "v 0 0\nv 1 0 0\n" + rest)), Contains("line 1: vertex 0 has fewer than 3"));
  CHECK_THAT(readError(dir.write("hash.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2#x 3\n")), Contains("2 corners"));
  CHECK(meshsweeper::readMesh(dir.write("extra.obj", "v 0 0 0 1 # w\nv 1 0 0 0.5 0.5 0.5\nv 0 1 0\nf 1 2 3 # one\n"))
            .triangles == one);
}

TEST_CASE("ASCII PLY: order kept, extra properties skipped, polygons fan-triangulated", "[mesh_io]") {
  TempDir dir;
  const Mesh mesh = meshsweeper::readMesh(dir.write("square.ply",
                                                    "ply\n"
                                                    "format ascii 1.0\n"
                                                    "comment written by the test\n"
                                                    "element vertex 5\n"
                                                    "property float x\n"
                                                    "property float y\n"
                                                    "property double z\n"
                                                    "property uchar red\n"
                                                    "property float confidence\n"
                                                    "element face 2\n"
                                                    "property list uchar int vertex_indices\n"
                                                    "property int flags\n"
                                                    "element edge 1\n"
                                                    "property int vertex1\n"
                                                    "property int vertex2\n"
                                                    "end_header\n"
                                                    "0 0 0 255 0.5\n"
                                                    "1 0 0 0 0.5\n"
                                                    "1 1 0 1 1e-3\n"
                                                    "0 1 0 2 -2\n"
                                                    "0.5 0.5 0.25 3 0\n"
                                                    "4 0 1 2 3 7\n"
                                                    "3 4 3 2 -1\n"
                                                    "0 1\n"));
  REQUIRE(mesh.positions.size() == 5);
  for (int v = 0; v < 4; ++v) CHECK(mesh.positions[v] == kSquare[v]);
  CHECK(mesh.positions[4] == Vec3(0.5, 0.5, 0.25));
  const std::vector<Triangle> expected = {{0, 1, 2}, {0, 2, 3}, {4, 3, 2}};
  CHECK(mesh.triangles == expected);
}

// A non-convex polygon whose first corner does not see all of it: the fan from that corner would
// cover area outside it (found by review: corner_poly.off read as overlapping triangles, whose
// distances and signs were wrong). It is cut into ears instead; a polygon its first corner
// sees whole keeps the fan.
TEST_CASE("polygons: the fan where it is right, ears where it is not", "[mesh_io]") {
  TempDir dir;
  // An L (area 3) listed from (2, 1), next to its reflex corner (1, 1): the fan's first
  // triangle (2,1), (1,1), (1,2) lies outside it.
  const Mesh l_shape = meshsweeper::readMesh(dir.write("l.off", "OFF\n6 1 0\n2 1 0\n1 1 0\n1 2 0\n0 2 0\n0 0 0\n2 0 0\n6 0 1 2 3 4 5\n"));
  REQUIRE(l_shape.triangles.size() == 4);
  double area = 0;
  for (const Triangle& t : l_shape.triangles) {
    const Vec3 n = (l_shape.positions[t[1]] - l_shape.positions[t[0]]).cross(l_shape.positions[t[2]] - l_shape.positions[t[0]]);
    area += 0.5 * n.norm();
    CHECK(n.z() > 0);  // the polygon's orientation kept
  }
  CHECK(area == Approx(3.0).epsilon(1e-15));
  CHECK(bruteForceClosest(l_shape, Vec3(1.3, 1.3, 0)).distance == Approx(0.3).epsilon(1e-12));
  // The same L listed from a corner that sees it whole: the fan, in order.
  const Mesh fanned = meshsweeper::readMesh(dir.write("l2.off", "OFF\n6 1 0\n0 0 0\n2 0 0\n2 1 0\n1 1 0\n1 2 0\n0 2 0\n6 0 1 2 3 4 5\n"));
  const std::vector<Triangle> fan = {{0, 1, 2}, {0, 2, 3}, {0, 3, 4}, {0, 4, 5}};
  CHECK(fanned.triangles == fan);
  auto covered = [](const Mesh& m) {
    double sum = 0;
    for (const Triangle& t : m.triangles) {
      const Vec3 n = (m.positions[t[1]] - m.positions[t[0]]).cross(m.positions[t[2]] - m.positions[t[0]]);
      sum += 0.5 * n.norm();
      if (n.z() < 0) sum += 1e9;  // an inverted triangle
    }
    return sum;
  };
  // Pinched: two corners at one position (different indices), area 2 (found by review: no ear
  // was cut, the fan covered 4 with an inverted triangle).
  const Mesh pinched = meshsweeper::readMesh(
      dir.write("pinched.off", "OFF\n6 1 0\n0 0 0\n2 0 0\n1 1 0\n2 2 0\n0 2 0\n1 1 0\n6 0 1 2 3 4 5\n"));
  CHECK(pinched.triangles.size() == 4);
  CHECK(covered(pinched) == Approx(2.0).epsilon(1e-15));
  // Two lobes touching at (2, 1), listed from a corner where the last ear would have been cut
  // from the spikes left over (found by review: a triangle (0,2), (2,1), (4,2) outside the
  // polygon, distance 0 at points 0.8 away); the touching corner as two vertices and as one.
  for (const char* text : {"OFF\n6 1 0\n0 0 0\n2 1 0\n4 0 0\n4 2 0\n2 1 0\n0 2 0\n6 0 1 2 3 4 5\n",
                           "OFF\n5 1 0\n0 0 0\n2 1 0\n4 0 0\n4 2 0\n0 2 0\n6 0 1 2 3 1 4\n"}) {
    const Mesh lobes = meshsweeper::readMesh(dir.write("lobes.off", text));
    INFO(text);
    CHECK(lobes.triangles.size() == 4);
    CHECK(covered(lobes) == Approx(4.0).epsilon(1e-15));
    CHECK(bruteForceClosest(lobes, Vec3(2, 1.9, 0)).distance == Approx(0.9 * 2 / std::sqrt(5.0)).epsilon(1e-12));
    CHECK(bruteForceClosest(lobes, Vec3(3, 1.8, 0)).distance == Approx(0.6 / std::sqrt(5.0)).epsilon(1e-12));
    CHECK(bruteForceClosest(lobes, Vec3(1, 0.5, 0)).distance == 0);  // inside a lobe
  }
  // A triangle and a square touching at a corner, listed from the triangle's far tip: the
  // spikes left over become degenerate triangles along edges, not a fan across the gap.
  const Mesh touching = meshsweeper::readMesh(dir.write(
      "touching.off", "OFF\n7 1 0\n0 0 0\n1 -1 0\n1 1 0\n1 -1 0\n3 -1 0\n3 1 0\n1 1 0\n7 2 0 1 3 4 5 6\n"));
  CHECK(touching.triangles.size() == 5);
  CHECK(covered(touching) == Approx(5.0).epsilon(1e-15));
  CHECK(bruteForceClosest(touching, Vec3(1.5, 0, 0)).distance == 0);
  CHECK(bruteForceClosest(touching, Vec3(0.5, 0.4, 0)).distance == 0);
  CHECK(bruteForceClosest(touching, Vec3(0.5, 0.6, 0)).distance == Approx(0.1 / std::sqrt(2.0)).epsilon(1e-12));
  // A star of 2,000 corners (radii 1 and 0.5 in turn) from a reflex corner: ears, exact area.
  std::string star = "OFF\n2000 1 0\n";
  double star_area = 0;
  std::vector<Vec3> corners;
  for (int i = 0; i < 2000; ++i) {
    const double angle = 2 * M_PI * i / 2000, radius = i % 2 ? 1.0 : 0.5;
    corners.emplace_back(radius * std::cos(angle), radius * std::sin(angle), 0);
  }
  for (const Vec3& c : corners) star += std::to_string(c.x()) + " " + std::to_string(c.y()) + " 0\n";
  star += "2000";
  for (int i = 0; i < 2000; ++i) star += " " + std::to_string(i);
  star += "\n";
  const Mesh star_mesh = meshsweeper::readMesh(dir.write("star.off", star));
  for (int i = 0; i < 2000; ++i) {
    const Vec3& a = star_mesh.positions[i];
    const Vec3& b = star_mesh.positions[(i + 1) % 2000];
    star_area += 0.5 * (a.x() * b.y() - b.x() * a.y());
  }
  CHECK(star_mesh.triangles.size() == 1998);
  CHECK(covered(star_mesh) == Approx(star_area).epsilon(1e-12));
}

TEST_CASE("polygons: ear cutting has a budget per file, past it non-convex polygons are fanned", "[mesh_io]") {
  // Found by review: one non-convex face of 8192 corners repeated 12 times took a minute to
  // read (ear cutting was capped per polygon only). The budget (README "Mesh input") is
  // 2^26 + 256 corner tests per corner of the file; cutting this star (radii 0.5 and 1 in turn,
  // from a reflex corner) takes about 3.7e7 of them, so of 4 copies (7.6e7) 2 are cut into ears,
  // the copy during which the budget runs out and the one after it are fanned whole.
  TempDir dir;
  constexpr int kCorners = 8192, kCopies = 4;
  std::string off = "OFF\n" + std::to_string(kCorners) + " " + std::to_string(kCopies) + " 0\n";
  for (int i = 0; i < kCorners; ++i) {
    const double angle = 2 * M_PI * i / kCorners, radius = i % 2 ? 1.0 : 0.5;
    off += std::to_string(radius * std::cos(angle)) + " " + std::to_string(radius * std::sin(angle)) + " 0\n";
  }
  std::string face = std::to_string(kCorners);
  for (int i = 0; i < kCorners; ++i) face += " " + std::to_string(i);
  for (int copy = 0; copy < kCopies; ++copy) off += face + "\n";
  const Mesh mesh = meshsweeper::readMesh(dir.write("stars.off", off));
  constexpr std::size_t kPerCopy = kCorners - 2;
  REQUIRE(mesh.triangles.size() == kCopies * kPerCopy);
  auto is_fan = [&](int copy) {
    for (std::size_t j = 0; j < kPerCopy; ++j) {
      const Triangle expected = {0, static_cast<meshsweeper::VertexIndex>(j + 1), static_cast<meshsweeper::VertexIndex>(j + 2)};
      if (mesh.triangles[copy * kPerCopy + j] != expected) return false;
    }
    return true;
  };
  // Ears: every triangle turns the polygon's way (+z), none of the fan's inverted ones.
  auto is_ears = [&](int copy) {
    for (std::size_t j = 0; j < kPerCopy; ++j) {
      const Triangle& t = mesh.triangles[copy * kPerCopy + j];
      if ((mesh.positions[t[1]] - mesh.positions[t[0]]).cross(mesh.positions[t[2]] - mesh.positions[t[0]]).z() <= 0)
        return false;
    }
    return true;
  };
  CHECK(is_ears(0));
  CHECK(is_ears(1));
  CHECK(is_fan(2));
  CHECK(is_fan(3));
}

TEST_CASE("polygons: a figure eight spends the budget on its area and spike checks", "[mesh_io]") {
  // Found by an audit: a self-crossing polygon of 8000 corners (a lobe of radius 1 turning
  // counter-clockwise, one of radius 0.7 clockwise, touching at the origin) took 16-36 s to
  // read. Once its cut ring enclosed nothing (the lobes' areas cancel), every ear also
  // re-measured the ring's area and its spikes, a pass or a quadratic scan over it, and the
  // budget did not count them. Now it does: the budget runs out on this polygon, which is
  // fanned whole, as a polygon during which it runs out is (README "Mesh input").
  TempDir dir;
  constexpr int kHalf = 4000;
  std::string off = "OFF\n" + std::to_string(2 * kHalf) + " 1 0\n";
  char line[128];
  for (int i = 0; i < kHalf; ++i) {
    const double a = M_PI + 2 * M_PI * i / kHalf;
    std::snprintf(line, sizeof line, "%.17g %.17g 0\n", 1 + std::cos(a), std::sin(a));
    off += line;
  }
  for (int i = 0; i < kHalf; ++i) {
    const double a = 2 * M_PI * i / kHalf;
    std::snprintf(line, sizeof line, "%.17g %.17g 0\n", -0.7 + 0.7 * std::cos(a), -0.7 * std::sin(a));
    off += line;
  }
  off += std::to_string(2 * kHalf);
  for (int i = 0; i < 2 * kHalf; ++i) off += " " + std::to_string(i);
  off += "\n";
  const Mesh mesh = meshsweeper::readMesh(dir.write("eight.off", off));
  REQUIRE(mesh.triangles.size() == 2 * kHalf - 2);
  bool fanned = true;
  for (std::size_t j = 0; j + 2 < 2 * kHalf && fanned; ++j)
    fanned = mesh.triangles[j] == Triangle{0, static_cast<meshsweeper::VertexIndex>(j + 1), static_cast<meshsweeper::VertexIndex>(j + 2)};
  CHECK(fanned);
}

TEST_CASE("binary PLY, little and big endian, float and double coordinates", "[mesh_io]") {
  TempDir dir;
  for (const bool big : {false, true}) {
    for (const bool doubles : {false, true}) {
      INFO("big endian " << big << ", double coordinates " << doubles);
      std::string s = std::string("ply\nformat ") +
                      (big ? "binary_big_endian" : "binary_little_endian") + " 1.0\n" +
                      "element vertex 5\n" +
                      (doubles ? "property double x\nproperty double y\nproperty double z\n"
                               : "property float x\nproperty float y\nproperty float z\n") +
                      "element face 2\nproperty list uchar uint vertex_indices\nend_header\n";
      const std::vector<Vec3> positions = {kSquare[0], kSquare[1], kSquare[2], kSquare[3],
                                           {0.5, 0.25, -0.125}};
      for (const Vec3& p : positions)
        for (int k = 0; k < 3; ++k) {
          if (doubles) putF64(s, p[k], big);
          else putF32(s, static_cast<float>(p[k]), big);
        }
      putU8(s, 5);
      for (std::uint32_t v : {0u, 1u, 4u, 2u, 3u}) putU32(s, v, big);
      putU8(s, 3);
      for (std::uint32_t v : {4u, 3u, 2u}) putU32(s, v, big);
      const Mesh mesh = meshsweeper::readMesh(dir.write("binary.ply", s));
      CHECK(mesh.positions == positions);
      const std::vector<Triangle> expected = {{0, 1, 4}, {0, 4, 2}, {0, 2, 3}, {4, 3, 2}};
      CHECK(mesh.triangles == expected);
    }
  }
}

// CGAL 5.5 reads coordinates only as float or double and indices only as int or uint: other
// integer types are re-encoded in memory for it (they were refused before).
TEST_CASE("PLY: integer coordinates and every integer index type read as float and int", "[mesh_io]") {
  TempDir dir;
  const std::vector<std::string> coordinate_types = {"float", "char",  "uchar", "short",  "ushort", "int",   "uint",
                                                     "int8",  "uint8", "int16", "uint16", "int32",  "uint32"};
  const std::vector<std::string> index_types = {"int",  "uint",  "char",  "uchar",  "short",
                                                "ushort", "int8", "uint8", "int16", "uint16"};
  for (const PlyTestFormat format : kPlyFormats) {
    for (const std::string& coordinate : coordinate_types) {
      for (const std::string& index : index_types) {
        for (const std::string count : {"uchar", "ushort"}) {
          INFO(plyFormatName(format) << ", coordinates " << coordinate << ", indices list " << count << " " << index);
          const PlyTestType type = plyTestType(coordinate);
          const TypedMesh expected = typedMesh(coordinate, plyTestType(index).bytes == 1 ? 100 : 300);
          // The same mesh as read before: float coordinates (double for 4-byte integers, which a
          // float does not hold) and int indices.
          const std::string reference_type = type.integer && type.bytes == 4 ? "double" : "float";
          const Mesh reference = meshsweeper::readMesh(dir.write(
              "reference.ply", typedPly(format, reference_type, "int", count, expected.positions, expected.faces)));
          const std::string path =
              dir.write("typed.ply", typedPly(format, coordinate, index, count, expected.positions, expected.faces));
          CHECK(readError(path) == "(no error)");
          if (readError(path) != "(no error)") continue;
          const Mesh mesh = meshsweeper::readMesh(path);
          CHECK(mesh.positions == expected.positions);
          CHECK(mesh.positions == reference.positions);
          CHECK(mesh.triangles == expected.triangles);
          CHECK(mesh.triangles == reference.triangles);
        }
      }
    }
  }
}

TEST_CASE("PLY: re-encoded files with 'vertex_index', a byte order mark or CRLF header lines", "[mesh_io]") {
  TempDir dir;
  const TypedMesh expected = typedMesh("short", 300);
  const std::string bom = "\xEF\xBB\xBF";
  for (const PlyTestFormat format : kPlyFormats) {
    for (const std::string index : {"int", "ushort", "char"}) {
      INFO(plyFormatName(format) << ", indices " << index);
      const TypedMesh& mesh = index == "char" ? typedMesh("short", 100) : expected;
      // 'vertex_index', CGAL's other name for the list.
      const Mesh named = meshsweeper::readMesh(dir.write(
          "named.ply", typedPly(format, "short", index, "uchar", mesh.positions, mesh.faces, true, "vertex_index")));
      CHECK(named.positions == mesh.positions);
      CHECK(named.triangles == mesh.triangles);
      // A byte order mark (dropped before the file is checked), CRLF header lines.
      const Mesh marked = meshsweeper::readMesh(
          dir.write("bom.ply", bom + typedPly(format, "short", index, "ushort", mesh.positions, mesh.faces)));
      CHECK(marked.positions == mesh.positions);
      CHECK(marked.triangles == mesh.triangles);
      const std::string crlf_file =
          typedPly(format, "int16", index, "uchar", mesh.positions, mesh.faces, true, "vertex_indices", "\r\n");
      const Mesh crlf = meshsweeper::readMesh(dir.write("crlf.ply", crlf_file));
      CHECK(crlf.positions == mesh.positions);
      CHECK(crlf.triangles == mesh.triangles);
    }
  }
}

TEST_CASE("PLY: bad indices and values of the re-encoded types are refused by name", "[mesh_io]") {
  TempDir dir;
  const std::vector<Vec3> three = {kSquare[0], kSquare[1], kSquare[2]};
  // readMesh's message for a file, which must name the file.
  const auto error = [&](const std::string& name, const std::string& bytes) {
    const std::string path = dir.write(name, bytes);
    const std::string message = readError(path);
    CHECK_THAT(message, StartsWith(path + ": "));
    return message;
  };
  for (const PlyTestFormat format : kPlyFormats) {
    INFO(plyFormatName(format));
    for (const std::string index : {"uchar", "char", "ushort", "short", "uint8", "int16"}) {
      INFO("indices " << index);
      CHECK_THAT(error("range.ply", typedPly(format, "short", index, "uchar", three, {{0, 1, 2}, {0, 1, 3}})),
                 Contains("face 1 uses vertex 3 but the file has 3 vertices"));
      if (!plyTestType(index).is_signed) continue;
      CHECK_THAT(error("negative.ply", typedPly(format, "float", index, "uchar", three, {{0, -1, 2}})),
                 Contains("face 0 uses the negative vertex index -1"));
      CHECK_THAT(error("negative2.ply", typedPly(format, "int", index, "ushort", three, {{0, 1, 2}, {2, 1, -2}})),
                 Contains("face 1 uses the negative vertex index -2"));
    }
    if (format == PlyTestFormat::kAscii) {
      // Each ASCII value is checked against its own type, not the one CGAL is given.
      const std::pair<const char*, std::int64_t> values[] = {
          {"uchar", 300}, {"uchar", -1}, {"char", 128}, {"ushort", 65536}};
      for (const auto& [index, value] : values) {
        INFO(index << " " << value);
        CHECK_THAT(error("value.ply", typedPly(format, "float", index, "uchar", three, {{0, value, 2}})),
                   Contains("PLY element 'face' item 0, 'vertex_indices': '" + std::to_string(value) +
                            "' is out of range for its type"));
      }
      CHECK_THAT(error("char_x.ply", typedPly(format, "char", "int", "uchar", {{0, 0, 0}, {128, 0, 0}, {0, 1, 0}},
                                              {{0, 1, 2}}, false)),
                 Contains("PLY element 'vertex' item 1, 'x': '128' is out of range for its type"));
      CHECK_THAT(error("int_y.ply", typedPly(format, "int", "int", "uchar", {{0, 0, 0}, {1, 0.5, 0}, {0, 1, 0}},
                                             {{0, 1, 2}}, false)),
                 Contains("PLY element 'vertex' item 1, 'y': '0.5' is not an integer"));
      continue;
    }
    // Truncated binary files: inside an index list, before a face's count, inside the vertices.
    const std::string whole = typedPly(format, "short", "ushort", "uchar", three, {{0, 1, 2}, {2, 1, 0}}, false);
    for (const std::size_t cut : {1, 2, 5})
      CHECK_THAT(error("cut.ply", whole.substr(0, whole.size() - cut)),
                 Contains("PLY element 'face' item 1: list 'vertex_indices' declares 3 entries but the file "
                          "ends first"));
    CHECK_THAT(error("no_count.ply", whole.substr(0, whole.size() - 7)),
               Contains("the file ends inside PLY element 'face' item 1 (truncated file)"));
    const std::size_t body = whole.find("end_header\n") + 11;
    CHECK_THAT(error("vertices.ply", whole.substr(0, body + 10)),
               Contains("PLY element 'vertex' declares 3 items of at least 6 bytes, but only 10 bytes are left"));
  }
}

TEST_CASE("ASCII STL: CGAL merges equal points, in order of first appearance", "[mesh_io]") {
  TempDir dir;
  const Mesh mesh = meshsweeper::readMesh(dir.write("square.stl",
                                                    "solid square\n"
                                                    "facet normal 0 0 1\n outer loop\n"
                                                    "  vertex 0 0 0\n  vertex 1 0 0\n  vertex 1 1 0\n"
                                                    " endloop\nendfacet\n"
                                                    "facet normal 0 0 1\n outer loop\n"
                                                    "  vertex 0 0 0\n  vertex 1 1 0\n  vertex 0 1 0\n"
                                                    " endloop\nendfacet\n"
                                                    "endsolid square\n"));
  CHECK(mesh.positions == kSquare);
  const std::vector<Triangle> expected = {{0, 1, 2}, {0, 2, 3}};
  CHECK(mesh.triangles == expected);
}

TEST_CASE("ASCII STL: what follows the last endsolid is ignored, names are not read", "[mesh_io]") {
  TempDir dir;
  const std::string facets = "facet normal 0 0 1\n outer loop\n  vertex 0 0 0\n  vertex 1 0 0\n  vertex 1 1 0\n"
                             " endloop\nendfacet\n"
                             "facet normal 0 0 1\n outer loop\n  vertex 0 0 0\n  vertex 1 1 0\n  vertex 0 1 0\n"
                             " endloop\nendfacet\n";
  const std::string square = "solid square\n" + facets + "endsolid square\n";
  const std::string far_facet = "facet normal 0 0 1\nouter loop\nvertex 50 50 50\nvertex 51 50 50\nvertex 50 51 50\n"
                                "endloop\nendfacet\n";
  const std::string one_line_facet = "facet vertex 50 50 50 vertex 51 50 50 vertex 50 51 50 endfacet";
  const std::vector<Triangle> expected = {{0, 1, 2}, {0, 2, 3}};
  // Found by review: a whole facet after the last 'endsolid' was added to the mesh (a
  // malformed one made the file refused), a tab after 'solid' made the file a truncated binary
  // STL, and 'solid' or 'facet' as a solid's name confused CGAL's reader.
  const std::pair<const char*, std::string> files[] = {
      {"facet after endsolid", square + far_facet},
      {"malformed facet after endsolid", square + "facet normal 0 0 0\nouter loop\nvertex 1 2 3\nendloop\nendfacet\n"},
      {"a word, then a solid, after endsolid", square + "junk\nsolid b\n" + far_facet + "endsolid b\n"},
      {"a facet on the endsolid line", "solid square\n" + facets + "endsolid square " + one_line_facet + "\n"},
      {"tab after solid", "solid\tsquare\n" + facets + "endsolid\tsquare\n"},
      {"tab after solid, no name", "solid\t\n" + facets + "endsolid\n"},
      {"named solid", "solid solid\n" + facets + "endsolid solid\n"},
      {"named facet", "solid facet\n" + facets + "endsolid facet\n"},
      {"named endsolid", "solid endsolid\n" + facets + "endsolid endsolid\n"},
      {"named with a facet", "solid a " + one_line_facet + "\n" + facets + "endsolid\n"}};
  for (const auto& [what, text] : files) {
    INFO(what);
    const std::string path = dir.write("square.stl", text);
    CHECK(readError(path) == "(no error)");
    if (readError(path) != "(no error)") continue;
    const Mesh mesh = meshsweeper::readMesh(path);
    CHECK(mesh.positions == kSquare);
    CHECK(mesh.triangles == expected);
  }
  // A second solid right after the first is read.
  const Mesh two = meshsweeper::readMesh(dir.write("two.stl", square + "solid far\n" + far_facet + "endsolid far\n"));
  CHECK(two.triangles.size() == 3);
}

TEST_CASE("binary STL, also with a header that starts with 'solid'", "[mesh_io]") {
  TempDir dir;
  const std::vector<std::array<Vec3, 3>> triangles = {{kSquare[0], kSquare[1], kSquare[2]},
                                                      {kSquare[0], kSquare[2], kSquare[3]}};
  // The last header spells out a facet (found by review: CGAL read it as ASCII first and kept
  // that facet before the file's own triangles).
  for (const std::string header : {"binary written by the test", "solid but binary", "solid\tbinary",
                                   "solid a facet vertex 5 5 5 vertex 6 5 5 vertex 5 6 5 endfacet"}) {
    INFO(header);
    const Mesh mesh = meshsweeper::readMesh(dir.write("square.stl", binaryStl(header, triangles, 2)));
    CHECK(mesh.positions == kSquare);  // 6 corners in the file, 4 distinct points
    const std::vector<Triangle> expected = {{0, 1, 2}, {0, 2, 3}};
    CHECK(mesh.triangles == expected);
  }
}

TEST_CASE("text files with a UTF-8 byte order mark or CR line ends read as without them", "[mesh_io]") {
  TempDir dir;
  const std::string bom = "\xEF\xBB\xBF";
  const std::vector<Triangle> expected = {{0, 1, 2}, {0, 2, 3}};
  const std::string files[][2] = {
      {"square.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n"},
      {"square.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n"},
      {"square.ply", "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                     "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                     "0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n"},
      {"square.stl", "solid square\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 1 1 0\n"
                     "endloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 1 0\n"
                     "vertex 0 1 0\nendloop\nendfacet\nendsolid square\n"}};
  for (const auto& [name, text] : files) {
    INFO(name);
    const Mesh mesh = meshsweeper::readMesh(dir.write(name, bom + text));
    CHECK(mesh.positions == kSquare);
    CHECK(mesh.triangles == expected);
    // The mark alone is an empty file of that format, and errors keep their line numbers.
    CHECK_THAT(readError(dir.write(name, bom)), Catch::Contains(name));
    CHECK(readError(dir.write(name, bom)) != "(no error)");
  }
  CHECK_THAT(readError(dir.write("bad.obj", bom + "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n")),
             Catch::Contains("line 4"));
  // Lines ended by CR alone (classic Mac OS) read as LF lines, with or without the mark; a PLY
  // (whose body may be binary, where a CR is data) is refused by name.
  for (const auto& [name, text] : files) {
    std::string cr = text;
    std::replace(cr.begin(), cr.end(), '\n', '\r');
    for (const std::string& mark : {std::string(), bom}) {
      INFO(name << (mark.empty() ? "" : " with the mark"));
      if (name == "square.ply") {
        CHECK_THAT(readError(dir.write(name, mark + cr)), Catch::Contains("its lines end in CR alone"));
        continue;
      }
      const Mesh mesh = meshsweeper::readMesh(dir.write(name, mark + cr));
      CHECK(mesh.positions == kSquare);
      CHECK(mesh.triangles == expected);
    }
  }
  CHECK_THAT(readError(dir.write("bad.off", "OFF\r3 1 0\r0 0 0\r1 0 0\r0 1 0\r3 0 1 3\r")),
             Catch::Contains("line 6: face 0 uses vertex 3"));
  // A CRLF file whose first line passes the 64 KiB the check looks at keeps its line numbers
  // (found by review: it was taken for CR-only and each CRLF made two lines).
  const std::string long_comment = "#" + std::string(65534, 'x') + "\r\n";  // its LF is byte 65537
  CHECK_THAT(readError(dir.write("long.off", long_comment + "OFF\r\n3 1 0\r\n0 0 0\r\n1 0\r\n0 1 0\r\n3 0 1 2\r\n")),
             Catch::Contains("line 5: vertex 1 has fewer than 3 coordinates"));
  // A binary STL with a 'solid' header, a wrong size and a CR byte (0x0D) in its data is not
  // repaired as text (its CR made a line break there): read as ASCII it has no 'endsolid'.
  const std::vector<std::array<Vec3, 3>> cr_triangle = {{Vec3(1.0000015, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)}};
  CHECK_THAT(readError(dir.write("cr.stl", binaryStl("solid part", cr_triangle, 1) + std::string(2, '\0'))),
             Catch::Contains("(the ASCII STL ends inside its solid") && Catch::Contains("nor a binary one"));
  // A binary STL whose header starts with the mark and 'solid' stays binary.
  const std::vector<std::array<Vec3, 3>> triangles = {{kSquare[0], kSquare[1], kSquare[2]},
                                                      {kSquare[0], kSquare[2], kSquare[3]}};
  const Mesh binary = meshsweeper::readMesh(dir.write("binary.stl", binaryStl(bom + "solid binary", triangles, 2)));
  CHECK(binary.positions == kSquare);
  CHECK(binary.triangles == expected);
}

TEST_CASE("readMesh refuses missing, unreadable and unknown files with 'PATH: problem'",
          "[mesh_io]") {
  TempDir dir;
  const std::string missing = dir.file("missing.off");
  CHECK_THAT(readError(missing), StartsWith(missing + ": ") && Contains("no such file"));
  CHECK_THAT(readError(dir.file("")), Contains("directory"));
  const std::string empty = dir.write("empty.off", "");
  CHECK_THAT(readError(empty), StartsWith(empty + ": ") && Contains("empty"));
  const std::string unknown = dir.write("mesh.xyz", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  CHECK_THAT(readError(unknown), StartsWith(unknown + ": ") && Contains("unknown extension"));
  CHECK_THAT(readError(dir.write("noextension", "OFF\n")), Contains("no file extension"));

  const std::string locked = dir.write("locked.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  std::filesystem::permissions(locked, std::filesystem::perms::none);
  if (geteuid() == 0) {
    WARN("running as root: permissions do not stop reading, unreadable-file check skipped");
  } else {
    CHECK_THAT(readError(locked), StartsWith(locked + ": ") && Contains("cannot open"));
  }
  std::filesystem::permissions(locked, std::filesystem::perms::owner_all);
}

TEST_CASE("readMesh refuses garbage in every format", "[mesh_io]") {
  TempDir dir;
  std::string noise;
  for (int i = 0; i < 3000; ++i) noise += static_cast<char>((i * 7919 + 13) % 251);
  for (const char* ext : {".off", ".obj", ".ply", ".stl"}) {
    for (const std::string& content : {noise, std::string("hello world\nthis is not a mesh\n")}) {
      const std::string path = dir.write(std::string("garbage") + ext, content);
      INFO(path);
      CHECK_THAT(readError(path), StartsWith(path + ": "));
    }
  }
  CHECK_THAT(readError(dir.write("words.off", "OFF\n3 1 0\n0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n")),
             Contains("line 4: vertex 1") && Contains("'zero'"));
  CHECK_THAT(readError(dir.write("short.off", "OFF\n3 1 0\n0 0 0\n1 0\n0 1 0\n3 0 1 2\n")),
             Contains("fewer than 3 coordinates"));
  CHECK_THAT(readError(dir.write("skel.off", "SKEL\n3 1\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n")),
             Contains("SKEL"));
  CHECK_THAT(readError(dir.write("noedges.off", "OFF\n3 1\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")),
             Contains("no edge count"));
  CHECK_THAT(readError(dir.write("bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nedge 1 2\nf 1 2 3\n")),
             Contains("line 4") && Contains("'edge'"));
  CHECK_THAT(readError(dir.write("short.obj", "v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n")),
             Contains("line 2") && Contains("fewer than 3"));
  CHECK_THAT(readError(dir.write("bad.stl", "solid x\nfacet normal 0 0 1\nouter loop\n"
                                            "vertex 0 0 0\nvertex 1 0 0\nendloop\nendfacet\n"
                                            "endsolid x\n")),
             Contains("facet 0 has 2 vertices (3 needed)"));
  for (const char* bad : {"nan", "inf", "1e400", "x"}) {
    CHECK_THAT(readError(dir.write("nan.stl", std::string("solid x\nfacet normal 0 0 1\nouter loop\n"
                                                          "vertex 0 0 0\nvertex ") + bad +
                                                  " 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid x\n")),
               Contains("line 5: vertex coordinate '" + std::string(bad) + "' is not a finite number"));
  }
  CHECK_THAT(readError(dir.write("big.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                            "property float y\nproperty float z\nelement face 1\n"
                                            "property list uchar int vertex_indices\nend_header\n"
                                            "0 0 0\n1e39 0 0\n0 1 0\n3 0 1 2\n")),
             Contains("'1e39' is too large for a float"));
  // FLT_MAX as printed for a round trip (3.40282347e+38, above FLT_MAX as a double) is a float.
  CHECK(meshsweeper::readMesh(dir.write("max.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                                   "property float y\nproperty float z\nproperty float quality\n"
                                                   "element face 1\nproperty list uchar int vertex_indices\n"
                                                   "end_header\n0 0 0 3.40282347e+38\n1 0 0 0\n0 1 0 0\n3 0 1 2\n"))
            .triangles.size() == 1);
  // Binary OFF: CGAL 5.5's soup reader misreads it, so it is refused outright.
  std::string binary_off = "OFF BINARY\n";
  for (std::uint32_t v : {3u, 1u, 0u}) putU32(binary_off, v, true);
  for (float c : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f, 0.f}) putF32(binary_off, c, true);
  for (std::uint32_t v : {3u, 0u, 1u, 2u, 0u}) putU32(binary_off, v, true);
  CHECK_THAT(readError(dir.write("binary.off", binary_off)), Contains("binary OFF"));
}

TEST_CASE("readMesh refuses PLY headers it cannot read safely", "[mesh_io]") {
  TempDir dir;
  const std::string start = "ply\nformat ascii 1.0\nelement vertex 3\n";
  const std::string body = "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  const std::string faces = "element face 1\nproperty list uchar int vertex_indices\n";
  // Integer coordinates and 2-byte indices are read (CGAL 5.5 dereferenced a null pointer on
  // the first and did not read the second: they were refused here; re-encoded for it now).
  const std::vector<Vec3> three = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  const std::vector<Triangle> one = {{0, 1, 2}};
  const Mesh int_xyz = meshsweeper::readMesh(
      dir.write("int.ply", start + "property int x\nproperty int y\nproperty int z\n" + faces + "end_header\n" + body));
  CHECK(int_xyz.positions == three);
  CHECK(int_xyz.triangles == one);
  // A list is no coordinate, nor a list of floats a list of indices.
  CHECK_THAT(readError(dir.write("list_x.ply", start + "property list uchar int x\nproperty int y\nproperty int z\n" +
                                                   faces + "end_header\n1 0 0 0\n1 1 0 0\n1 0 1 0\n3 0 1 2\n")),
             Contains("PLY element 'vertex': 'x' is a list, not a coordinate"));
  CHECK_THAT(readError(dir.write("noz.ply", start + "property float x\nproperty float y\n" + faces +
                                                "end_header\n0 0\n1 0\n0 1\n3 0 1 2\n")),
             Contains("no 'z'"));
  const std::string xyz = "property float x\nproperty float y\nproperty float z\n";
  CHECK_THAT(readError(dir.write("type.ply", start + xyz + "property uint64 id\n" + faces +
                                                 "end_header\n" + body)),
             Contains("unknown type 'uint64'"));
  const Mesh short_index = meshsweeper::readMesh(dir.write("short_index.ply",
                                 start + xyz + "element face 1\nproperty list uchar ushort vertex_indices\n"
                                     "end_header\n" + body));
  CHECK(short_index.positions == three);
  CHECK(short_index.triangles == one);
  CHECK_THAT(readError(dir.write("float_index.ply",
                                 start + xyz + "element face 1\nproperty list uchar float vertex_indices\n"
                                     "end_header\n" + body)),
             Contains("PLY element 'face' needs a 'vertex_indices' list of integers ('vertex_indices' is a list "
                      "of float)"));
  CHECK_THAT(readError(dir.write("scalar_index.ply",
                                 start + xyz + "element face 1\nproperty uchar vertex_index\n"
                                     "end_header\n0 0 0\n1 0 0\n0 1 0\n3\n")),
             Contains("PLY element 'face' needs a 'vertex_indices' list of integers ('vertex_index' is uchar)"));
  CHECK_THAT(readError(dir.write("no_index.ply",
                                 start + xyz + "element face 1\nproperty list uchar int corners\n"
                                     "end_header\n" + body)),
             EndsWith("PLY element 'face' needs a 'vertex_indices' list of integers"));
  CHECK_THAT(readError(dir.write("noend.ply", start + xyz + faces)),
             Contains("the PLY header has no end_header (truncated file?)"));
  // Found by review: a header cut inside a line (no line break at its end) was said to have no
  // end_header "in the first 1048576 bytes".
  for (const std::string& cut : {std::string("ply\nformat binary_little_endian 1."), start + "property double x",
                                start + "element verte"}) {
    INFO(cut);
    CHECK_THAT(readError(dir.write("cut.ply", cut)),
               Contains("the PLY header has no end_header (the file ends inside header line") &&
                   Contains("truncated file?)") && !Contains("1048576"));
  }
  CHECK_THAT(readError(dir.write("nofaces.ply", start + xyz + "end_header\n0 0 0\n1 0 0\n0 1 0\n")),
             Contains("no faces"));
  CHECK_THAT(readError(dir.write("word.ply", start + xyz + faces + "end_header\n0 0 0\n1 x 0\n0 1 0\n3 0 1 2\n")),
             Contains("item 1") && Contains("'x' is not a number"));
  CHECK_THAT(readError(dir.write("inf.ply", start + xyz + faces + "end_header\n0 0 0\n1 inf 0\n0 1 0\n3 0 1 2\n")),
             Contains("'inf' is not finite"));
  // Found by review: colour properties of mixed names and types crashed CGAL's reader.
  const std::string mixed = "property uchar red\nproperty float green\nproperty uchar g\nproperty uchar blue\n";
  CHECK_THAT(readError(dir.write("mixed.ply", start + xyz + mixed + faces + "end_header\n0 0 0 1 0.5 2 3\n"
                                              "1 0 0 1 0.5 2 3\n0 1 0 1 0.5 2 3\n3 0 1 2\n")),
             Contains("PLY element 'vertex': colour property 'green' is float, but the others make it read as uchar"));
  CHECK_THAT(readError(dir.write("mixed_face.ply", start + xyz + "element face 1\nproperty list uchar int vertex_indices\n" +
                                                   "property uchar r\nproperty uchar green\nproperty list uchar int g\n"
                                                   "property uchar b\nend_header\n" + "0 0 0\n1 0 0\n0 1 0\n" +
                                                   "3 0 1 2 1 2 1 3 4\n")),
             Contains("PLY element 'face': colour property 'g' is a list"));
  const Mesh coloured = meshsweeper::readMesh(dir.write(
      "colour.ply", start + xyz + "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty float g\n" +
                        faces + "end_header\n0 0 0 1 2 3 0.5\n1 0 0 1 2 3 0.5\n0 1 0 1 2 3 0.5\n3 0 1 2\n"));
  CHECK(coloured.triangles.size() == 1);
  CHECK(coloured.positions[1] == Vec3(1, 0, 0));
}

TEST_CASE("readMesh refuses truncated files", "[mesh_io]") {
  TempDir dir;
  // Short enough for the header check.
  const std::string off = dir.write("cut.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n");
  CHECK_THAT(readError(off), StartsWith(off + ": ") && Contains("truncated"));
  // Long lines pass the header check; the body scan names what is missing.
  CHECK_THAT(readError(dir.write("cut2.off", "OFF\n4 2 0\n0.000000 0.000000 0.000000\n"
                                             "1.000000 0.000000 0.000000\n1.000000 1.000000 0.000000\n"
                                             "0.000000 1.000000 0.000000\n3 0 1 2\n")),
             Contains("ends after 1 face of the 2 declared"));
  CHECK_THAT(readError(dir.write("cut3.off", "OFF\n4 2 0\n0.000000 0.000000 0.000000\n"
                                             "1.000000 0.000000 0.000000\n1.000000 1.000000 0.000000\n"
                                             "0.000000 1.000000 0.000000\n3 0 1 2\n3 0 2\n")),
             Contains("line 8: face 1 declares 3 corners but lists 2 indices"));

  std::string ply = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                    "property float y\nproperty float z\nelement face 1\n"
                    "property list uchar int vertex_indices\nend_header\n";
  for (int k = 0; k < 9; ++k) putF32(ply, static_cast<float>(k));
  putU8(ply, 3);
  putU32(ply, 0);
  putU32(ply, 1);  // one index missing
  CHECK_THAT(readError(dir.write("cut.ply", ply)), Contains("list 'vertex_indices'"));
  CHECK_THAT(readError(dir.write("cut_ascii.ply",
                                 "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                 "property float y\nproperty float z\nelement face 1\n"
                                 "property list uchar int vertex_indices\nend_header\n"
                                 "0 0 0\n1 0 0\n0 1 0\n3 0 1\n")),
             Contains("ends inside PLY element 'face' item 0"));

  const std::vector<std::array<Vec3, 3>> one = {{kSquare[0], kSquare[1], kSquare[2]}};
  std::string stl = binaryStl("binary", one, 2);  // declares 2, holds 1
  CHECK_THAT(readError(dir.write("cut.stl", stl)), Contains("declares 2 triangles") && Contains("truncated"));
  stl = binaryStl("binary", one, 1);
  stl.resize(stl.size() - 10);
  CHECK_THAT(readError(dir.write("cut2.stl", stl)), Contains("truncated"));
  CHECK_THAT(readError(dir.write("tiny.stl", "abc")), Contains("too short for a binary STL"));
  CHECK_THAT(readError(dir.write("cut_ascii.stl", "solid x\nfacet normal 0 0 1\nouter loop\n"
                                                  "vertex 0 0 0\nvertex 1 0 0\n")),
             Contains("truncated"));
  // Found by review: a binary count below the data read part of the file silently, and an ASCII
  // file under 80 bytes lost its malformed facet (CGAL's binary retry called it empty).
  stl = binaryStl("binary", {one[0], one[0], one[0]}, 2);
  CHECK_THAT(readError(dir.write("count_low.stl", stl)),
             Contains("declares 2 triangles (184 bytes) but the file has 50 more bytes (a wrong triangle count?)"));
  stl = binaryStl("binary", one, 1) + "garbage!";
  CHECK_THAT(readError(dir.write("extra.stl", stl)), Contains("8 more bytes"));
  CHECK_THAT(readError(dir.write("short.stl", "solid\nfacet vertex 0 0 0 vertex 1 0 0 vertex 0 1 0 endfacet\nfacet\nendsolid")),
             Contains("line 4: 'endsolid' inside facet 1"));
  CHECK_THAT(readError(dir.write("two_vertices.stl", "solid x\nfacet normal 0 0 1\nouter loop\n"
                                                     "vertex 0 0 0\nvertex 1 0 0\nendloop\nendfacet\nendsolid x\n")),
             Contains("line 7: facet 0 has 2 vertices (3 needed)"));
  CHECK_THAT(readError(dir.write("stray.stl", "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n"
                                              "vertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nbogus\nendsolid x\n")),
             Contains("line 9: expected 'facet' or 'endsolid', found 'bogus'"));
  // Found by review of the check: exporters write 'nan' normals for degenerate facets (CGAL does
  // not read normals), and what follows the last 'endsolid' (a DOS end-of-file byte) is ignored.
  const std::string nan_normal = "solid t\nfacet normal -nan -nan -nan\nouter loop\nvertex 0 0 0\nvertex 0 0 0\n"
                                 "vertex 1 0 0\nendloop\nendfacet\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n"
                                 "vertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n";
  CHECK(meshsweeper::readMesh(dir.write("nan_normal.stl", nan_normal)).triangles.size() == 2);
  CHECK(meshsweeper::readMesh(dir.write("ctrl_z.stl", nan_normal + "\x1a")).triangles.size() == 2);
  CHECK(meshsweeper::readMesh(dir.write("trailing.stl", nan_normal + "written by hand\n")).triangles.size() == 2);
  // A binary file whose header starts with 'solid ' and which has bytes past its triangles.
  CHECK_THAT(readError(dir.write("solid_padded.stl", binaryStl("solid part", one, 1) + std::string(2, '\0'))),
             Contains("nor a binary one: its header declares 1 triangle (134 bytes) but the file has 2 more bytes"));
  CHECK_THAT(readError(dir.write("normal_word.stl", "solid x\nfacet normal endfacet 0 0\nouter loop\nvertex 0 0 0\n"
                                                    "vertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid x\n")),
             Contains("line 2: the normal of facet 0 has 'endfacet' among its 3 numbers"));
  // A truncated binary file whose header starts with 'solid': its binary bytes name it binary.
  CHECK_THAT(readError(dir.write("solid_cut.stl", binaryStl("solid part", one, 2))),
             Contains("a binary STL (its header starts with 'solid', but binary data follows): it declares 2 "
                      "triangles, which need 184 bytes, but the file has 134 (truncated file)"));
  // Upper-case keywords are no ASCII STL (nor is its first line a binary count).
  CHECK_THAT(readError(dir.write("upper.stl", "SOLID x\nFACET NORMAL 0 0 1\nOUTER LOOP\nVERTEX 0 0 0\n"
                                              "VERTEX 1 0 0\nVERTEX 0 1 0\nENDLOOP\nENDFACET\nENDSOLID x\n")),
             Contains("not an ASCII STL: it starts with 'SOLID', and ASCII STL keywords are lowercase"));
  // One line per facet, no 'outer loop', two solids: valid.
  const Mesh flat = meshsweeper::readMesh(dir.write("flat.stl",
      "solid a\nfacet vertex 0 0 0 vertex 1 0 0 vertex 0 1 0 endfacet\nendsolid a\n"
      "solid b\nfacet normal 0 0 1 outer loop vertex 0 0 0 vertex 0 1 0 vertex -1 0 0 endloop endfacet endsolid\n"));
  CHECK(flat.triangles.size() == 2);
}

TEST_CASE("readMesh refuses absurd counts before allocating for them", "[mesh_io]") {
  TempDir dir;
  const std::string off = dir.write("huge.off", "OFF 1000000000000 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  CHECK_THAT(readError(off), StartsWith(off + ": ") && Contains("1000000000000 vertices"));
  CHECK_THAT(readError(dir.write("huge_faces.off", "OFF\n3 2000000000 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")),
             Contains("2000000000 faces"));
  CHECK_THAT(readError(dir.write("huge_count.off", "OFF\n3 99999999999999999999 0\n0 0 0\n")),
             Contains("face count"));
  CHECK_THAT(readError(dir.write("huge_face.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n1000000000 0 1 2\n")),
             Contains("1000000000 corners"));

  const std::string ascii_ply = dir.write(
      "huge.ply", "ply\nformat ascii 1.0\nelement vertex 1000000000000\nproperty float x\n"
                  "property float y\nproperty float z\nelement face 1\n"
                  "property list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  CHECK_THAT(readError(ascii_ply), StartsWith(ascii_ply + ": ") && Contains("1000000000000 items"));

  std::string ply = "ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\n"
                    "property float x\nproperty float y\nproperty float z\nelement face 1\n"
                    "property list uchar int vertex_indices\nend_header\n";
  for (int k = 0; k < 9; ++k) putF32(ply, static_cast<float>(k));
  CHECK_THAT(readError(dir.write("huge_binary.ply", ply)), Contains("1000000000000 items"));

  // A list length CGAL would resize to (1.6 GB) before finding the file short.
  std::string list = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                     "property float y\nproperty float z\nelement face 1\n"
                     "property list uint int vertex_indices\nend_header\n";
  for (int k = 0; k < 9; ++k) putF32(list, static_cast<float>(k));
  putU32(list, 400000000);
  for (std::uint32_t v : {0u, 1u, 2u}) putU32(list, v);
  CHECK_THAT(readError(dir.write("huge_list.ply", list)), Contains("declares 400000000 entries"));
  CHECK_THAT(readError(dir.write("huge_list_ascii.ply",
                                 "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                 "property float y\nproperty float z\nelement face 1\n"
                                 "property list uint int vertex_indices\nend_header\n"
                                 "0 0 0\n1 0 0\n0 1 0\n4000000000 0 1 2\n")),
             Contains("declares 4000000000 entries"));

  const std::vector<std::array<Vec3, 3>> one = {{kSquare[0], kSquare[1], kSquare[2]}};
  CHECK_THAT(readError(dir.write("huge.stl", binaryStl("binary", one, 4000000000u))),
             Contains("declares 4000000000 triangles"));
}

TEST_CASE("readMesh refuses non-finite coordinates", "[mesh_io]") {
  TempDir dir;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  CHECK_THAT(readError(dir.write("nan.off", "OFF\n3 1 0\n0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n")),
             Contains("vertex 1") && Contains("not a finite number"));
  CHECK_THAT(readError(dir.write("big.off", "OFF\n3 1 0\n0 0 0\n1 1e999 0\n0 1 0\n3 0 1 2\n")),
             Contains("vertex 1") && Contains("not a finite number"));
  // Homogeneous OFF with w = 0: CGAL divides by it.
  const std::string homogeneous =
      dir.write("w0.off", "4OFF\n3 1 0\n0 0 0 1\n1 0 0 0\n0 1 0 1\n3 0 1 2\n");
  CHECK_THAT(readError(homogeneous),
             StartsWith(homogeneous + ": line 4: vertex 1: its coordinates divided by its weight '0'"));
  CHECK_THAT(readError(dir.write("w_tiny.off", "4OFF\n3 1 0\n0 0 0 1\n1 0 0 1\n0 1e300 0 1e-300\n3 0 1 2\n")),
             Contains("line 5: vertex 2: its coordinates divided by its weight '1e-300'"));
  CHECK(meshsweeper::readMesh(dir.write("w2.off", "4OFF\n3 1 0\n0 0 0 2\n2 0 0 2\n0 4 0 2\n3 0 1 2\n"))
            .positions[2] == Vec3(0, 2, 0));
  CHECK_THAT(readError(dir.write("nan.obj", "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")),
             Contains("line 2: vertex 1"));
  for (const float bad : {nan, inf, -inf}) {
    std::string ply = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                      "property float y\nproperty float z\nelement face 1\n"
                      "property list uchar int vertex_indices\nend_header\n";
    for (float c : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f, bad}) putF32(ply, c);
    putU8(ply, 3);
    for (std::uint32_t v : {0u, 1u, 2u}) putU32(ply, v);
    CHECK_THAT(readError(dir.write("nan.ply", ply)), Contains("vertex 2 has a non-finite coordinate"));
    const std::vector<std::array<Vec3, 3>> one = {{kSquare[0], Vec3(1, bad, 0), kSquare[2]}};
    CHECK_THAT(readError(dir.write("nan.stl", binaryStl("binary", one, 1))),
               Contains("triangle 0 has a non-finite coordinate"));
  }
}

// CGAL's readers parse OFF indices as doubles and truncate them, read an OBJ corner as the
// integer its token starts with and split corners on spaces only; readMesh checks first.
TEST_CASE("readMesh refuses indices that are not integers, and data past the declared faces", "[mesh_io]") {
  TempDir dir;
  const std::string head = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n";
  for (const char* bad : {"0.9", "-0.5", "1.5", "1e0"}) {
    const std::string path = dir.write("index.off", head + "3 0 " + bad + " 2\n");
    CHECK_THAT(readError(path), StartsWith(path + ": line 6: face 0: index '" + bad + "' is not an integer"));
  }
  CHECK_THAT(readError(dir.write("count.off", head + "3.5 0 1 2\n")), Contains("'3.5' is not a corner count"));
  // Integers past 64 bits are integers out of range, and the message says so.
  const std::string huge(300, '9');
  CHECK_THAT(readError(dir.write("huge_index.off", head + "3 0 1 " + huge + "\n")),
             Contains("line 6: face 0 uses vertex '9999") && Contains("...' but the file has 3 vertices"));
  CHECK_THAT(readError(dir.write("huge_negative.off", head + "3 0 1 -" + huge + "\n")),
             Contains("line 6: face 0 uses vertex '-9999"));
  CHECK_THAT(readError(dir.write("huge_corners.off", head + huge + " 0 1 2\n")),
             Contains("line 6: face 0: corner count '9999") && Contains("...' is out of range"));
  CHECK_THAT(readError(dir.write("huge_vertices.off", "OFF\n" + huge + " 1 0\n")),
             Contains("the OFF header's vertex count has more than 18 digits (out of range)"));
  CHECK_THAT(readError(dir.write("huge_faces.off", "OFF\n3 " + huge + " 0\n")),
             Contains("the OFF header's face count has more than 18 digits (out of range)"));
  CHECK_THAT(readError(dir.write("huge_edges.off", "OFF\n3 1 " + huge + "\n")),
             Contains("the OFF header's edge count has more than 18 digits"));
  // Leading zeros are not digits of the count.
  CHECK(meshsweeper::readMesh(dir.write("zeros.off", "OFF\n00000000000000000000003 0001 0\n" + head.substr(10) + "3 0 1 2\n"))
            .triangles.size() == 1);
  const std::string ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                          "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                          "0 0 0\n1 0 0\n0 1 0\n";
  CHECK_THAT(readError(dir.write("huge_index.ply", ply + "3 0 1 " + huge + "\n")),
             Contains("'vertex_indices': '9999") && Contains("...' is out of range for its type"));
  CHECK_THAT(readError(dir.write("huge_count.ply", "ply\nformat ascii 1.0\nelement vertex " + huge + "\nend_header\n")),
             Contains("PLY header line 3: element 'vertex' count '9999") && Contains("...' is out of range"));
  // A face the header does not count, or trailing text, is refused, not dropped.
  CHECK_THAT(readError(dir.write("more.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n5 5 5\n3 0 1 2\n3 1 2 3\n")),
             Contains("line 8: more data after the 1 face the header declares"));
  CHECK_THAT(readError(dir.write("tail.off", head + "3 0 1 2\nend\n")), Contains("line 7: more data after"));
  // Found by an audit: vertices written several to a line (free-format OFF) made the file "end
  // after 1 face": the message now points at the line that holds more than a vertex. A fourth
  // number alone is read as before (CGAL ignores it).
  CHECK_THAT(readError(dir.write("crowded.off", "OFF\n4 2 0\n0 0 0 1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n")),
             Contains("the file ends after 1 face of the 2 declared (line 3 holds 6 numbers where a vertex of OFF "
                      "takes 3: OFF is read one vertex, and one face, a line)"));
  CHECK(meshsweeper::readMesh(dir.write("fourth.off", "OFF\n3 1 0\n0 0 0 9\n1 0 0\n0 1 0\n3 0 1 2\n")).positions ==
        std::vector<Vec3>{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
  // Found by review: no hint where the line is innocent: a fourth number alone, or a face read
  // as a vertex because the header counts one vertex too many.
  CHECK_THAT(readError(dir.write("fourth_bad.off", "OFF\n3 1 0\n0 0 0 1\n1 0 0\n0 1 0\n3 0 1 5\n")),
             Contains("face 0 uses vertex 5") && !Contains("holds"));
  CHECK_THAT(readError(dir.write("count.off", "OFF\n6 2 0\n0 0 0\n1 0 0\n1 1 0\n0.5 2 0\n0 1 0\n5 0 1 2 3 4\n3 0 1 2\n")),
             Contains("the file ends after 1 face of the 2 declared") && !Contains("holds"));
  // Comments and blank lines after the faces are fine; so are per-face colours.
  CHECK(meshsweeper::readMesh(dir.write("ok.off", head + "3 0 1 2 255 0 0 # red\n\n# end\n")).triangles.size() == 1);
  // So is a DOS end-of-file byte (0x1A) as the last word of a text file, in every text format;
  // one followed by more data is refused.
  const std::string ply_head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                               "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                               "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  for (const auto& [name, text] : {std::pair<std::string, std::string>{"eof.off", head + "3 0 1 2\n\x1a"},
                                   {"eof.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n\x1a"},
                                   {"eof.ply", ply_head + "\x1a"},
                                   {"eof.stl", "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
                                               "vertex 0 1 0\nendloop\nendfacet\nendsolid t\n\x1a"}}) {
    INFO(name);
    CHECK(meshsweeper::readMesh(dir.write(name, text)).triangles.size() == 1);
  }
  CHECK_THAT(readError(dir.write("eof2.off", head + "3 0 1 2\n\x1a\n3 0 1 2\n")), Contains("line 8: more data after"));
  CHECK_THAT(readError(dir.write("eof3.off", head + "3 0 1 2\n\x1a\x1a")), Contains("line 7: more data after"));
  CHECK_THAT(readError(dir.write("eof2.ply", ply_head + "\x1a 1")), Contains("more data"));
  CHECK(readError(dir.write("eof2.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\x1a")) != "(no error)");

  const std::string verts = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n";
  for (const char* bad : {"f 1 2.5 3", "f 1 3abc 2", "f 1 2 3 x", "f 1/ 2 3", "f /1 2 3"}) {
    INFO(bad);
    CHECK_THAT(readError(dir.write("bad.obj", verts + bad + "\n")), Contains("line 5: face 0") && Contains("is not a vertex index"));
  }
  CHECK_THAT(readError(dir.write("zero.obj", "f 0 1 2\n" + verts)), Contains("line 1: face 0: OBJ index 0 is not valid"));
  CHECK_THAT(readError(dir.write("relative.obj", "v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n")),
             Contains("line 3: face 0 uses OBJ index -3 but only 2 vertices precede it"));
  // Tabs separate corners as spaces do; 'v/t/n' forms, relative indices and comments are read.
  for (const char* good : {"f\t1\t2 4", "f 1/1\t2/2/2 4//4", "f -4 -3 -1 # a comment"}) {
    INFO(good);
    const Mesh mesh = meshsweeper::readMesh(dir.write("good.obj", verts + good + "\n"));
    REQUIRE(mesh.triangles.size() == 1);
    CHECK(mesh.triangles[0] == Triangle{0, 1, 3});
  }
}

TEST_CASE("readMesh refuses out-of-range indices and faces with fewer than 3 corners",
          "[mesh_io]") {
  TempDir dir;
  CHECK_THAT(readError(dir.write("range.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n")),
             Contains("line 6: face 0 uses vertex 5 but the file has 3 vertices"));
  CHECK_THAT(readError(dir.write("negative.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n")),
             Contains("face 0 uses vertex -1"));
  // CGAL's OBJ reader lets index n+1 (one past the end) through; readMesh does not.
  CHECK_THAT(readError(dir.write("range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n")),
             Contains("line 4: face 0 uses OBJ index 4 but the file has 3 vertices"));
  CHECK_THAT(readError(dir.write("range2.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n")),
             Contains("line 5: face 1 uses OBJ index 9 but the file has 3 vertices"));
  // Found by an audit: a statement CGAL does not know ('V', uppercase) is the problem, named at
  // its line, not the face that then lacks a vertex.
  CHECK_THAT(readError(dir.write("upper.obj", "V 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n")),
             Contains("upper.obj: line 1: unsupported OBJ statement 'V'"));
  CHECK_THAT(readError(dir.write("later.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\nvx 1\nf 1 2 4\n")),
             Contains("later.obj: line 5: unsupported OBJ statement 'vx'"));
  // Indices past 64 bits are out of range, not malformed: the message says which index.
  const std::string huge(300, '9');
  CHECK_THAT(readError(dir.write("huge_v.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 -" + huge + " 3\n")),
             Contains("line 4: face 0 uses OBJ index '-9999") && Contains("...', out of range (the file has 3 vertices)"));
  CHECK_THAT(readError(dir.write("huge_t.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/" + huge + " 2 3\n")),
             Contains("line 5: face 0: '1/9999") && Contains("has a texture index out of range ('9999"));
  CHECK_THAT(readError(dir.write("huge_n.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//+" + huge + " 2 3\n")),
             Contains("line 4: face 0: '1//+9999") && Contains("has a normal index out of range ('+9999"));
  const std::string ply_start = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                "property float y\nproperty float z\nelement face 1\n"
                                "property list uchar int vertex_indices\nend_header\n"
                                "0 0 0\n1 0 0\n0 1 0\n";
  CHECK_THAT(readError(dir.write("range.ply", ply_start + "3 0 1 3\n")),
             Contains("face 0 uses vertex 3 but the file has 3 vertices"));
  // Found by review: a negative PLY index was reported as 18446744073709551615.
  CHECK_THAT(readError(dir.write("negative.ply", ply_start + "3 0 -1 2\n")),
             Contains("face 0 uses the negative vertex index -1"));
  CHECK_THAT(readError(dir.write("two.off", "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n2 0 1\n")),
             Contains("face 1 has 2 corners (at least 3 needed)"));
  CHECK_THAT(readError(dir.write("zero.off", "OFF\n3 2 0\n0 0 0.5\n1 0 0.5\n0 1 0.5\n3 0 1 2\n0\n")),
             Contains("face 1 has 0 corners"));
  CHECK_THAT(readError(dir.write("two.ply", ply_start + "2 0 1\n")),
             Contains("face 0 has 2 corners"));
  // Data past the elements the header declares (a face it does not count) is refused.
  CHECK_THAT(readError(dir.write("extra.ply", ply_start + "3 0 1 2\n3 2 1 0\n")),
             Contains("more data ('3') after the last element the header declares"));
  CHECK(meshsweeper::readMesh(dir.write("fine.ply", ply_start + "3 0 1 2\n\n")).triangles.size() == 1);
  std::string binary = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                       "property float y\nproperty float z\nelement face 1\n"
                       "property list uchar int vertex_indices\nend_header\n";
  for (float c : {0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f, 0.f}) putF32(binary, c);
  putU8(binary, 3);
  for (std::uint32_t v : {0u, 1u, 2u}) putU32(binary, v);
  CHECK(meshsweeper::readMesh(dir.write("fine_binary.ply", binary)).triangles.size() == 1);
  CHECK(meshsweeper::readMesh(dir.write("newline_binary.ply", binary + "\n")).triangles.size() == 1);
  // Up to 16 blank bytes after the last element are a text editor's trailing newlines; more are
  // refused, as any other data would be (a mutation test found no test of the limit).
  CHECK(meshsweeper::readMesh(dir.write("blank16_binary.ply", binary + std::string(16, '\n'))).triangles.size() == 1);
  for (size_t blanks : {17, 64})
    CHECK_THAT(readError(dir.write("blank_binary.ply", binary + std::string(blanks, ' '))),
               Contains(std::to_string(blanks) + " bytes follow the last element the header declares"));
  std::string negative_binary = binary.substr(0, binary.size() - 4);
  putU32(negative_binary, 0xfffffffeu);  // int -2
  CHECK_THAT(readError(dir.write("negative_binary.ply", negative_binary)),
             Contains("face 0 uses the negative vertex index -2"));
  putU32(binary, 7);
  CHECK_THAT(readError(dir.write("extra_binary.ply", binary)),
             Contains("4 bytes follow the last element the header declares"));
}

// The same check on a mesh built in memory (checkMesh, which Hierarchy::build calls): one past
// the last vertex is out of range.
TEST_CASE("checkMesh refuses out-of-range indices of a mesh built in memory", "[mesh_io]") {
  Mesh mesh;
  mesh.name = "built";
  mesh.positions = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)};
  mesh.triangles = {Triangle{0, 1, 2}, Triangle{2, 1, 3}};
  CHECK(meshsweeper::checkMesh(mesh) == "built: triangle 1 uses vertex 3 but the mesh has 3 vertices");
  mesh.triangles[1] = Triangle{2, 1, 0};
  CHECK(meshsweeper::checkMesh(mesh).empty());
}

TEST_CASE("readMesh refuses meshes without faces", "[mesh_io]") {
  TempDir dir;
  const std::string off = dir.write("points.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n");
  CHECK_THAT(readError(off), StartsWith(off + ": ") && Contains("no faces"));
  CHECK_THAT(readError(dir.write("points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n")), Contains("no faces"));
  CHECK_THAT(readError(dir.write("empty.stl", "solid empty\nendsolid empty\n")), Contains("no faces"));
  CHECK_THAT(readError(dir.write("empty_binary.stl", binaryStl("binary", {}, 0))),
             Contains("no faces"));
  CHECK_THAT(readError(dir.write("spaces.stl", "   \n\n")), StartsWith(dir.file("spaces.stl")));
}

TEST_CASE("writeOff writes what readMesh reads back exactly", "[mesh_io]") {
  TempDir dir;
  Mesh mesh;
  mesh.name = "awkward";
  mesh.positions = {{0.1, 1.0 / 3.0, -0.0}, {1e-300, -2.5e17, 123456789.123456789},
                    {std::nextafter(1.0, 2.0), 0, 0}, {7, 7, 7}};
  mesh.triangles = {{0, 1, 2}, {2, 1, 0}, {0, 0, 2}};
  const std::string path = dir.file("out.off");
  meshsweeper::writeOff(mesh, path);
  const Mesh back = meshsweeper::readMesh(path);
  CHECK(back.positions == mesh.positions);  // isolated vertex 3 kept too
  CHECK(back.triangles == mesh.triangles);
  CHECK_THROWS_AS(meshsweeper::writeOff(mesh, dir.file("no/such/folder/out.off")), MeshError);
}

// Found by review: a property declared twice was taken once (the other ignored), and a value
// written with over 512 characters was cut there, its end read as the next value.
TEST_CASE("ASCII PLY: repeated properties refused, long values read whole", "[mesh_io]") {
  TempDir dir;
  const std::string twice = dir.write("twice.ply",
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "9 0 0 0\n9 1 0 0\n9 0 1 0\n3 0 1 2\n");
  CHECK_THAT(readError(twice), Contains("PLY header line 5: property 'x' declared twice in element 'vertex'"));
  // Found by an audit: a face list under both names was read from one, and two vertex (face)
  // elements one after the other; which is meant is not said, so both are refused by name.
  const std::string xyz = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
  CHECK_THAT(readError(dir.write("both_lists.ply", xyz +
                                 "element face 1\nproperty list uchar int vertex_indices\n"
                                 "property list uchar int vertex_index\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 3 0 2 1\n")),
             Contains("both_lists.ply") && Contains("has both 'vertex_indices' and 'vertex_index' lists"));
  CHECK_THAT(readError(dir.write("two_vertex.ply", xyz +
                                 "element vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
                                 "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
                                 "0 0 0\n1 0 0\n0 1 0\n5 5 5\n3 0 1 3\n")),
             Contains("two_vertex.ply") && Contains("two vertex elements is ambiguous"));
  CHECK_THAT(readError(dir.write("two_face.ply", xyz +
                                 "element face 1\nproperty list uchar int vertex_indices\n"
                                 "element faces 1\nproperty list uchar int vertex_indices\nend_header\n"
                                 "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 2 1\n")),
             Contains("PLY element 'faces' follows element 'face'") && Contains("two face elements is ambiguous"));
  // A second element of no items reads nothing: read as one (found by review).
  CHECK(meshsweeper::readMesh(dir.write("empty_second.ply", xyz +
                                        "element face 1\nproperty list uchar int vertex_indices\n"
                                        "element face 0\nproperty list uchar int vertex_indices\nend_header\n"
                                        "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"))
            .triangles.size() == 1);
  const Mesh mesh = meshsweeper::readMesh(dir.write("long.ply",
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
      "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0." + std::string(600, '0') + " 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"));
  CHECK(mesh.positions == std::vector<Vec3>{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}});
}

// Found by an audit: a read error on standard input (a directory, a closed descriptor) was
// taken for its end (zero points, success), and one in a points file (/proc/self/mem fails its
// first read) gave the C++ library's message without the file's name.
// Found by an audit: one line ending in CR alone among LF-ended ones was read with the next as
// one line by CGAL's OBJ reader, which dropped what followed the CR (a vertex lost, answers
// silently wrong).
TEST_CASE("OBJ: a CR inside a line is refused by its line number", "[mesh_io]") {
  TempDir dir;
  const std::string path = dir.write("lone_cr.obj", "v 0 0 0\nv 1 0 0\rv 5 5 5\nv 0 1 0\nf 1 2 3\n");
  CHECK_THROWS_WITH(meshsweeper::readMesh(path), Contains("lone_cr.obj") && Contains("line 2: a CR inside the line"));
  // CRLF ends, and a CR before trailing blanks, are line ends as before.
  const Mesh crlf = meshsweeper::readMesh(dir.write("crlf.obj", "v 0 0 0\r\nv 1 0 0 \r \nv 0 1 0\r\nf 1 2 3\r\n"));
  CHECK(crlf.positions.size() == 3);
  CHECK(crlf.triangles.size() == 1);
}

TEST_CASE("readPoints: read errors name the input", "[mesh_io]") {
  if (std::filesystem::exists("/proc/self/mem"))
    CHECK_THROWS_WITH(meshsweeper::readPoints("/proc/self/mem"),
                      Contains("/proc/self/mem: read error (Input/output error)"));
  // Standard input that is a directory: every read fails (EISDIR).
  std::fflush(stdout);
  const int saved = dup(0);
  const int directory = open("/", O_RDONLY | O_DIRECTORY);
  REQUIRE(saved >= 0);
  REQUIRE(directory >= 0);
  REQUIRE(dup2(directory, 0) == 0);
  std::string message;
  try {
    meshsweeper::readPoints("-");
  } catch (const MeshError& e) {
    message = e.what();
  }
  dup2(saved, 0);
  close(saved);
  close(directory);
  std::clearerr(stdin);
  std::cin.clear();
  CHECK_THAT(message, Contains("<stdin>: read error (Is a directory)"));
}

TEST_CASE("readPoints: one point a line, comments and blank lines ignored", "[mesh_io]") {
  TempDir dir;
  const std::string path = dir.write("points.txt",
                                     "# query points\n"
                                     "0 0 0\n"
                                     "\n"
                                     "  1.5\t-2e3  +3   # trailing comment\n"
                                     "   \t \n"
                                     "1e-400 .5 -0.25\r\n"
                                     "7 8 9");
  const std::vector<Vec3> points = meshsweeper::readPoints(path);
  const std::vector<Vec3> expected = {{0, 0, 0}, {1.5, -2000, 3}, {0, 0.5, -0.25}, {7, 8, 9}};
  CHECK(points == expected);
  CHECK(meshsweeper::readPoints(dir.write("empty.txt", "")).empty());
  // A UTF-8 byte order mark is dropped, before a comment too.
  const std::vector<Vec3> one = {{1, 2, 3}};
  CHECK(meshsweeper::readPoints(dir.write("bom.txt", "\xEF\xBB\xBF# points\n1 2 3\n")) == one);
  CHECK(meshsweeper::readPoints(dir.write("bom2.txt", "\xEF\xBB\xBF" "1 2 3")) == one);
  CHECK_THAT(pointsError(dir.write("ef.txt", "\xEF" "1 2 3\n")), Catch::Contains("ef.txt:1: not a points file"));
}

TEST_CASE("readPoints refuses malformed lines with 'PATH:LINE: problem'", "[mesh_io]") {
  TempDir dir;
  const std::string two = dir.write("two.txt", "0 0 0\n# comment\n1 2\n");
  CHECK_THAT(pointsError(two), StartsWith(two + ":3: ") && Contains("found 2 fields"));
  const std::string four = dir.write("four.txt", "1 2 3 4\n");
  CHECK_THAT(pointsError(four), StartsWith(four + ":1: ") && Contains("found 4 fields"));
  const std::string word = dir.write("word.txt", "1 2 3\n1 two 3\n");
  CHECK_THAT(pointsError(word), StartsWith(word + ":2: ") && Contains("'two' is not a number"));
  // Bytes that are not printable are shown as C escapes, not '?' (found by an audit).
  const std::string escape = dir.write("escape.txt", "1 2 3\n1 \x1b[31m3 3\n");
  CHECK_THAT(pointsError(escape), StartsWith(escape + ":2: ") && Contains("'\\x1b[31m3' is not a number"));
  const std::string control = dir.write("control.txt", "1 2 3\x1a\n");
  CHECK_THAT(pointsError(control), Contains("'3\\x1a' is not a number"));
  const std::string comma = dir.write("comma.txt", "1,2,3\n");
  CHECK_THAT(pointsError(comma), StartsWith(comma + ":1: "));
  for (const char* bad : {"nan", "inf", "-inf", "1e999"}) {
    const std::string path = dir.write("bad.txt", std::string("0 0 ") + bad + "\n");
    CHECK_THAT(pointsError(path), StartsWith(path + ":1: ") && Contains("not finite"));
  }
  const std::string huge = dir.write("huge.txt", "0 0 0\n0.2 0.2 1e155\n");
  CHECK_THAT(pointsError(huge), StartsWith(huge + ":2: ") && Contains("'1e155'") && Contains("beyond 1e150"));
  CHECK(meshsweeper::readPoints(dir.write("limit.txt", "-1e150 0 1e150\n")).size() == 1);
  const std::string missing = dir.file("missing.txt");
  CHECK_THAT(pointsError(missing), StartsWith(missing + ": ") && Contains("no such file"));
  // A line without end (found by review: /dev/zero grew one until memory ran out).
  const std::string endless = dir.write("endless.txt", "0 0 0\n" + std::string(3 << 20, '0'));
  CHECK_THAT(pointsError(endless), StartsWith(endless + ":2: ") && Contains("line longer than 1048576 bytes"));
  // Lines ended by CR alone are refused as such (found by review: the message counted 6 fields).
  const std::string cr = dir.write("cr.txt", "1 2 3\r4 5 6\r");
  CHECK_THAT(pointsError(cr), StartsWith(cr + ":1: ") && Contains("CR alone"));
  const std::string crlf_four = dir.write("crlf4.txt", "1 2 3 4\r\n");  // a CRLF end is no CR-only line
  CHECK_THAT(pointsError(crlf_four), Contains("found 4 fields"));
}

TEST_CASE("readPoints reads standard input for '-'", "[mesh_io]") {
  std::istringstream input("1 2 3\n# comment\n4 5 6\n");
  std::streambuf* saved = std::cin.rdbuf(input.rdbuf());
  std::vector<Vec3> points;
  std::string error;
  try {
    points = meshsweeper::readPoints("-");
  } catch (const MeshError& e) {
    error = e.what();
  }
  std::cin.rdbuf(saved);
  CHECK(error.empty());
  const std::vector<Vec3> expected = {{1, 2, 3}, {4, 5, 6}};
  CHECK(points == expected);

  std::istringstream bad("1 2 3\nx\n");
  saved = std::cin.rdbuf(bad.rdbuf());
  try {
    meshsweeper::readPoints("-");
  } catch (const MeshError& e) {
    error = e.what();
  }
  std::cin.rdbuf(saved);
  CHECK_THAT(error, StartsWith("<stdin>:2: "));
}

TEST_CASE("real meshes from data/meshes load with their file counts", "[mesh_io][data]") {
  struct Expected {
    const char* name;
    size_t vertices;
    size_t triangles;
  };
  const Expected meshes[] = {{"armadillo", 26002, 52000},        {"bunny00", 37706, 75408},
                             {"refined_elephant", 44460, 88928}, {"holes", 4291, 8288},
                             {"mannequin-devil", 12977, 25888}};
  for (const Expected& e : meshes) {
    const std::string path = std::string(MESHSWEEPER_DATA_DIR) + "/" + e.name + ".off";
    if (!std::filesystem::exists(path)) {
      WARN(path << " missing (run scripts/fetch_data.sh): skipped");
      continue;
    }
    INFO(path);
    const Mesh mesh = meshsweeper::readMesh(path);
    CHECK(mesh.positions.size() == e.vertices);
    CHECK(mesh.triangles.size() == e.triangles);
  }
}
