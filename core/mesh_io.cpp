// Reading meshes and point lists (core/mesh_io.h).
//
// Meshes are read by CGAL 5.5's polygon-soup readers, which keep the file's vertex and face order,
// except binary STL, read here (a simple fixed layout, which CGAL misread after a "solid" header).
// Those readers trust their input, so every file is checked before CGAL sees it:
//
//   OFF  The header is parsed here and its counts compared with the file size (CGAL resizes its
//        arrays to the header counts). Binary OFF is refused: CGAL 5.5's soup reader ignores the
//        per-face colour count of binary OFF and misreads every face after the first.
//   PLY  The header is parsed and the body walked without storing anything: element counts
//        against the file size, every list length against the bytes left (CGAL resizes to it),
//        every ASCII value against its type, and the property types (an unknown type makes
//        CGAL misread the rest of the file). CGAL 5.5 reads coordinates only as float or double
//        (an 'int x' made it dereference a null pointer) and face indices only as int or uint:
//        a file with integer coordinates or 1- or 2-byte index items is given to CGAL re-encoded
//        in memory, those coordinates as double and those indices as int or uint (reencodePly).
//   STL  A binary file is read here (its triangle count must match the file size, its
//        coordinates be finite); an ASCII file's structure is checked word by word before CGAL
//        reads it (checkStl), and CGAL is given its text up to the last 'endsolid' line, names
//        blanked (checkAsciiStl).
//   OBJ  Nothing to check ahead: CGAL grows its arrays while it reads.
// CGAL's readers only say true or false; when they say false for an OFF or OBJ file, the file is
// scanned again here to name the line and the problem.
//
// Polygons are handed to CGAL as Corners, whose resize() refuses absurd corner counts (an OFF
// face line "1000000000 0 1 2" would otherwise allocate 8 GB before the line is found short).
// After CGAL: polygons with fewer than 3 corners and out-of-range indices are refused (CGAL's OBJ
// reader lets index n+1 through), polygons are triangulated (the fan, or ears where the fan
// is wrong: triangulatePolygon), and checkMesh() has the last word.
#include "core/mesh_io.h"

#include <CGAL/IO/OBJ.h>
#include <CGAL/IO/OFF.h>
#include <CGAL/IO/PLY.h>
#include <CGAL/IO/STL.h>
#include <CGAL/Simple_cartesian.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <array>
#include <cstring>
#include <map>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <locale>
#include <new>
#include <iterator>
#include <sstream>
#include <string_view>

namespace meshsweeper {
namespace {

using Kernel = CGAL::Simple_cartesian<double>;
using CgalPoint = Kernel::Point_3;

// Largest polygon accepted (8 MB of indices); a face line claiming more is refused before
// anything is allocated for it.
constexpr std::size_t kMaxPolygonCorners = std::size_t(1) << 20;
// Largest PLY header looked at before giving up, in bytes.
constexpr std::size_t kMaxPlyHeaderBytes = std::size_t(1) << 20;
// Smallest ASCII OFF vertex line ("0 0 0\n") and face line ("3 0 1 2" + newline, minus slack).
constexpr std::uint64_t kMinOffVertexBytes = 6;
constexpr std::uint64_t kMinOffFaceBytes = 6;
// Most vertices and faces an OFF file may declare in all: CGAL's header reader estimates
// 2.1 (vertices + faces + 10) half-edges in an int (found by fuzzing, with its edge count).
constexpr std::uint64_t kMaxOffElements = 1000000000;

enum class Format { kOff, kObj, kPly, kStl };

[[noreturn]] void fail(const std::string& path, const std::string& problem) {
  throw MeshError(path + ": " + problem);
}

// "1 face", "2 faces", "2 vertices", "2 indices".
std::string plural(std::uint64_t n, const std::string& word) {
  if (n == 1) return "1 " + word;
  if (word == "vertex") return std::to_string(n) + " vertices";
  if (word == "index") return std::to_string(n) + " indices";
  return std::to_string(n) + " " + word + "s";
}

// Thrown by Corners::resize through CGAL's reader; turned into a MeshError by readMesh.
struct TooManyCorners {
  std::size_t count;
};

// A polygon as CGAL fills it: a vector of vertex indices whose resize() refuses absurd counts.
class Corners : public std::vector<std::size_t> {
 public:
  void resize(std::size_t n) {
    if (n > kMaxPolygonCorners) throw TooManyCorners{n};
    std::vector<std::size_t>::resize(n);
  }
};

// ---------------------------------------------------------------------------------------------
// Small parsing helpers.

// The UTF-8 byte order mark some editors write at the start of a text file.
constexpr std::string_view kUtf8Bom = "\xEF\xBB\xBF";

bool isBlank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

std::vector<std::string_view> splitWords(std::string_view line) {
  std::vector<std::string_view> words;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (isBlank(line[i]) || line[i] == '\n')) ++i;
    const std::size_t begin = i;
    while (i < line.size() && !isBlank(line[i]) && line[i] != '\n') ++i;
    if (i > begin) words.push_back(line.substr(begin, i - begin));
  }
  return words;
}

enum class NumberStatus { kOk, kNotANumber, kNonFinite };

// Parses a whole word as a double, locale-independently. Accepts a leading '+'; a value too small
// for a double becomes 0 (or a denormal); overflow, "inf" and "nan" give kNonFinite.
NumberStatus parseDouble(std::string_view word, double& value) {
  if (word.size() > 1 && word[0] == '+' && word[1] != '-' && word[1] != '+') word.remove_prefix(1);
  const char* end = word.data() + word.size();
  auto [ptr, ec] = std::from_chars(word.data(), end, value);
  if (ec == std::errc::result_out_of_range && ptr == end) {
    // Overflow or underflow: the classic-locale stream tells them apart (it fails on overflow).
    std::istringstream stream{std::string(word)};
    stream.imbue(std::locale::classic());
    double v = 0;
    if (!(stream >> v)) return NumberStatus::kNonFinite;
    value = v;
    return NumberStatus::kOk;
  }
  if (ec != std::errc() || ptr != end) return NumberStatus::kNotANumber;
  return std::isfinite(value) ? NumberStatus::kOk : NumberStatus::kNonFinite;
}

// Parses a whole word as a decimal integer (optional sign).
bool parseInteger(std::string_view word, std::int64_t& value) {
  if (word.size() > 1 && word[0] == '+' && word[1] != '-' && word[1] != '+') word.remove_prefix(1);
  const char* end = word.data() + word.size();
  auto [ptr, ec] = std::from_chars(word.data(), end, value);
  return ec == std::errc() && ptr == end;
}

// Whether a word that parseInteger refused is an integer all the same, one too large for 64
// bits (a sign, then digits only): its message then says "out of range", not "not an index".
bool isHugeInteger(std::string_view word) {
  if (!word.empty() && (word[0] == '+' || word[0] == '-')) word.remove_prefix(1);
  return !word.empty() && std::all_of(word.begin(), word.end(), [](char c) { return c >= '0' && c <= '9'; });
}

// A word of the file, quoted for a message: its first 40 bytes, a byte that is not printable
// ASCII written as its C escape, so that the message stays one line and says what the file
// holds.
std::string shown(std::string_view word) {
  constexpr std::size_t kShown = 40;
  return "'" + escapedText(word.substr(0, kShown), true) + (word.size() > kShown ? "...'" : "'");
}

// ---------------------------------------------------------------------------------------------
// Opening.

// Opens path for binary reading and returns its size in bytes. Throws MeshError for a missing,
// unreadable or empty file, a directory or a special file (a FIFO could block forever).
std::uint64_t openInput(const std::string& path, std::ifstream& in) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status status = fs::status(path, ec);
  if (status.type() == fs::file_type::not_found) fail(path, "no such file");
  if (ec) fail(path, "cannot access the file (" + ec.message() + ")");
  if (status.type() == fs::file_type::directory) fail(path, "is a directory, not a file");
  if (status.type() != fs::file_type::regular) fail(path, "not a regular file");
  const std::uintmax_t size = fs::file_size(path, ec);
  if (ec) fail(path, "cannot read the file size (" + ec.message() + ")");
  errno = 0;
  in.open(path, std::ios::in | std::ios::binary);
  if (!in.is_open())
    fail(path, std::string("cannot open the file (") +
                   (errno != 0 ? std::strerror(errno) : "unknown reason") + ")");
  if (size == 0) fail(path, "the file is empty");
  return size;
}

Format formatOf(const std::string& path) {
  const std::string ext_raw = std::filesystem::path(path).extension().string();
  std::string ext;
  for (char c : ext_raw) ext += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".off") return Format::kOff;
  if (ext == ".obj") return Format::kObj;
  if (ext == ".ply") return Format::kPly;
  if (ext == ".stl") return Format::kStl;
  fail(path, (ext.empty() ? std::string("no file extension") : "unknown extension " + shown(ext)) +
                 " (expected .off, .obj, .ply or .stl)");
}

// ---------------------------------------------------------------------------------------------
// OFF.

struct OffHeader {
  std::uint64_t vertices = 0;
  std::uint64_t faces = 0;
  std::uint64_t body_offset = 0;  // bytes before the first vertex line
  // The keyword's prefixes ([ST][C][N][4]OFF): what CGAL reads on each vertex line after its
  // 3 (4OFF: 4) coordinates: a normal (N, 3 or 4 numbers), colours (C: on vertex and face
  // lines), texture coordinates (ST: 2 or 3 numbers, last).
  bool textures = false, colors = false, normals = false, homogeneous = false;
  std::string keyword;
  std::uint64_t keyword_offset = 0;  // where the keyword starts
};

// Skips whitespace and whole '#' comments, as CGAL's skip_comment_OFF does.
void skipOffSpaceAndComments(std::istream& in) {
  int c;
  while ((c = in.peek()) != EOF) {
    if (c == '#') {
      while ((c = in.get()) != EOF && c != '\n') {}
    } else if (std::isspace(c)) {
      in.get();
    } else {
      break;
    }
  }
}

std::string readOffWord(std::istream& in, std::size_t max_chars) {
  std::string word;
  int c;
  while (word.size() < max_chars && (c = in.peek()) != EOF && std::isalnum(c))
    word += static_cast<char>(in.get());
  return word;
}

// Reads a non-negative header count: kInvalid when the next word is not one, kTooLarge when it
// has more than 18 digits past its leading zeros (10^18 or more: no file holds that many).
enum class OffCount { kOk, kInvalid, kTooLarge };
OffCount readOffCount(std::istream& in, std::uint64_t& count) {
  const std::string digits = readOffWord(in, 32);
  const bool cut = std::isalnum(in.peek());  // the word goes on past 32 characters
  if (digits.empty()) return OffCount::kInvalid;
  for (char c : digits)
    if (!std::isdigit(static_cast<unsigned char>(c))) return OffCount::kInvalid;
  const std::size_t first = digits.find_first_not_of('0');
  const std::size_t significant = first == std::string::npos ? 0 : digits.size() - first;
  if (cut || significant > 18) return OffCount::kTooLarge;
  count = significant == 0 ? 0 : std::stoull(digits.substr(first));
  return OffCount::kOk;
}

// A header count's failure, named.
void checkOffCount(const std::string& path, OffCount status, const char* what) {
  if (status == OffCount::kTooLarge)
    fail(path, std::string("the OFF header's ") + what + " count has more than 18 digits (out of range)");
  if (status != OffCount::kOk) fail(path, std::string("the OFF header has no valid ") + what + " count");
}

// Parses the OFF header the way CGAL's File_header_OFF does and checks its counts against the
// file size. Throws MeshError.
OffHeader checkOffHeader(const std::string& path, std::istream& in, std::uint64_t file_size) {
  skipOffSpaceAndComments(in);
  OffHeader header;
  header.keyword_offset = static_cast<std::uint64_t>(in.tellg());
  const std::string keyword = readOffWord(in, 16);
  // CGAL's keyword grammar: [ST][C][N][4][n]OFF, or SKEL.
  std::size_t j = 0;
  if (keyword.compare(j, 2, "ST") == 0) j += 2, header.textures = true;
  if (j < keyword.size() && keyword[j] == 'C') ++j, header.colors = true;
  if (j < keyword.size() && keyword[j] == 'N') ++j, header.normals = true;
  if (j < keyword.size() && keyword[j] == '4') ++j, header.homogeneous = true;
  header.keyword = keyword;
  const bool n_dimensional = j < keyword.size() && keyword[j] == 'n';
  if (n_dimensional) ++j;
  if (keyword.substr(j) != "OFF") {
    if (keyword.size() >= 4 && keyword.substr(keyword.size() - 4) == "SKEL")
      fail(path, "a SKEL file has no faces, expected an OFF mesh");
    fail(path, "not an OFF file (the header does not start with 'OFF')");
  }
  if (n_dimensional) fail(path, "n-dimensional OFF (" + keyword + ") is not supported");
  if (in.peek() == '#')  // CGAL's reader fails there
    fail(path, "a comment right after the '" + keyword + "' keyword (put a blank before the '#')");

  skipOffSpaceAndComments(in);
  if (std::isalpha(in.peek())) {
    if (readOffWord(in, 16) == "BINARY")
      fail(path, "binary OFF is not supported (CGAL 5.5 misreads its faces); convert it to ASCII "
                 "OFF or PLY");
    fail(path, "the OFF header has no vertex count");
  }
  checkOffCount(path, readOffCount(in, header.vertices), "vertex");
  while (std::isspace(in.peek())) in.get();
  if (in.peek() == '#')  // CGAL's reader fails there
    fail(path, "the OFF header has a comment between its vertex and face counts (write the counts "
               "on one line, the comment after them)");
  checkOffCount(path, readOffCount(in, header.faces), "face");
  // CGAL reads the edge count wherever it is, so a header without one swallows the first
  // coordinate; insist that it follows on the same line.
  while (isBlank(static_cast<char>(in.peek()))) in.get();
  std::uint64_t edges = 0;
  const OffCount edge_count = readOffCount(in, edges);
  if (edge_count == OffCount::kTooLarge)
    fail(path, "the OFF header's edge count has more than 18 digits (it is not read: write 0)");
  if (edge_count != OffCount::kOk)
    fail(path, "the OFF header line with the vertex and face counts has no edge count (write "
               "'" + std::to_string(header.vertices) + " " + std::to_string(header.faces) +
               " 0')");
  // CGAL reads the count as an int and doubles it in an int (found by fuzzing: 2^30 overflowed).
  if (edges > static_cast<std::uint64_t>(std::numeric_limits<int>::max() / 2))
    fail(path, "the OFF header's edge count " + std::to_string(edges) + " is too large (it is not read: write 0)");
  // CGAL reads the rest of the counts' line as vertex 0's (found by review: '3 1 0 9 9 9' made
  // (9, 9, 9) vertex 0, and every vertex one later): only blanks and a comment may follow.
  std::string rest;
  int c;
  while ((c = in.get()) != EOF && c != '\n') rest += static_cast<char>(c);
  if (!in && !in.eof()) fail(path, "read error in the OFF header");
  const std::size_t word = rest.find_first_not_of(" \t\r\v\f");
  if (word != std::string::npos && rest[word] != '#') {
    const std::string_view after = std::string_view(rest).substr(word);
    fail(path, "the OFF header line has more after its counts: " + shown(after.substr(0, after.find_first_of(" \t\r"))) +
                   " (CGAL would read it as vertex 0: put each vertex on a line of its own)");
  }
  in.clear();
  const std::streamoff position = in.tellg();
  header.body_offset = position < 0 ? file_size : static_cast<std::uint64_t>(position);

  if (header.faces == 0) fail(path, "the OFF header declares no faces");
  if (header.vertices == 0) fail(path, "the OFF header declares no vertices");
  const std::uint64_t body = file_size - std::min(file_size, header.body_offset);
  // Counts have at most 18 digits, so 6 * (vertices + faces) < 1.2e19 cannot overflow.
  if (header.vertices > body || header.faces > body ||
      kMinOffVertexBytes * header.vertices + kMinOffFaceBytes * header.faces > body + 1) {
    fail(path, "the OFF header declares " + plural(header.vertices, "vertex") + " and " +
                   plural(header.faces, "face") + ", which need at least " +
                   std::to_string(kMinOffVertexBytes * header.vertices +
                                  kMinOffFaceBytes * header.faces) +
                   " bytes, but only " + std::to_string(body) +
                   " bytes follow the header (truncated file or wrong counts)");
  }
  if (header.vertices + header.faces > kMaxOffElements)
    fail(path, "the OFF header declares " + plural(header.vertices, "vertex") + " and " + plural(header.faces, "face") +
                   ": more than " + std::to_string(kMaxOffElements) + " in all, which CGAL's OFF reader cannot count");
  return header;
}

// A line longer than nextDataLine's max_line (line_number is the one before it).
struct LineTooLong {};

// std::getline, or, with a max_line, a read that stops there (a special file without line
// breaks, /dev/zero, would grow one line without end).
bool readLine(std::istream& in, std::string& line, std::size_t max_line) {
  if (max_line == std::string::npos) return static_cast<bool>(std::getline(in, line));
  std::streambuf& buffer = *in.rdbuf();
  line.clear();
  int c = buffer.sbumpc();
  if (c == EOF) return false;
  for (; c != EOF && c != '\n'; c = buffer.sbumpc()) {
    if (line.size() == max_line) throw LineTooLong{};
    line.push_back(static_cast<char>(c));
  }
  return true;
}

// Reads the next line that is not blank and not a whole-line comment, without its '#' comment.
// Returns false at the end of the file; throws LineTooLong past max_line characters.
bool nextDataLine(std::istream& in, std::string& line, std::uint64_t& line_number,
                  std::size_t max_line = std::string::npos) {
  while (readLine(in, line, max_line)) {
    ++line_number;
    const std::size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    if (!splitWords(line).empty()) return true;
  }
  return false;
}

// Checks an ASCII OFF body the way CGAL's scanner reads it (one vertex or face a line, '#'
// comments), more strictly: CGAL parses a face's corner count and indices as doubles and
// truncates them (0.9 becomes 0, -0.5 becomes 0), and ignores whatever follows the declared
// faces; here they must be integers and nothing but comments may follow. Returns the first
// problem ("line L: ..."), or an empty string.
// A COFF line's colour: `count` numbers from words[first]. CGAL takes 1 as an index into its
// colour map (cast to int: a negative or huge one reads outside the map) and 3 or more as
// red, green, blue; 2 makes it read past them.
// Once a vertex (face) has a colour, CGAL reads one for every later vertex (face): from past the
// end of its numbers where it has none (found under ASan), so `coloured` carries that.
std::string checkOffColor(const std::vector<std::string_view>& words, std::size_t first, std::size_t count,
                          const char* element, bool& coloured) {
  if (count == 0 && coloured)
    return std::string("no colour, but an earlier ") + element + " has one (colour every " + element + " or none)";
  if (count == 0) return {};
  coloured = true;
  if (count == 2) return "a colour needs 1, 3 or 4 numbers, not 2";
  if (count != 1) return {};
  double index = 0;
  if (parseDouble(words[first], index) != NumberStatus::kOk || !(index >= 0) ||
      index > std::numeric_limits<int>::max() || std::floor(index) != index)
    return "colour-map index " + shown(words[first]) + " is not a whole number from 0 up";
  return {};
}

std::string checkOffBody(std::istream& in, const OffHeader& header) {
  in.clear();
  in.seekg(0);
  std::string line;
  std::uint64_t line_number = 0;
  // Skip to the header's end by line counting: the body starts after the line holding it.
  while (static_cast<std::uint64_t>(in.tellg()) < header.body_offset && std::getline(in, line))
    ++line_number;
  bool vertex_colours = false, face_colours = false;  // COFF: a vertex (face) before had a colour
  // The first vertex line with numbers enough for two vertices (no colours declared): CGAL
  // ignores those past the first, but where the file then fails, vertices written several to a
  // line (a free-format OFF) are the likely cause, and the message says so (found by an audit:
  // such a file was said to end after its first face).
  std::uint64_t crowded_line = 0, crowded_numbers = 0, crowded_needed = 0;
  auto hinted = [&](std::string problem) {
    if (crowded_line != 0)
      problem += " (line " + std::to_string(crowded_line) + " holds " + std::to_string(crowded_numbers) +
                 " numbers where a vertex of " + header.keyword + " takes " + std::to_string(crowded_needed) +
                 ": OFF is read one vertex, and one face, a line)";
    return problem;
  };
  for (std::uint64_t v = 0; v < header.vertices; ++v) {
    if (!nextDataLine(in, line, line_number))
      return hinted("the file ends after " + plural(v, "vertex") + " of the " +
                    std::to_string(header.vertices) + " declared");
    const auto words = splitWords(line);
    std::size_t numbers = 0;
    for (std::string_view w : words) {
      double value;
      if (parseDouble(w, value) != NumberStatus::kOk) {
        if (numbers >= 3) break;  // CGAL stops at the first word that is not a number
        return hinted("line " + std::to_string(line_number) + ": vertex " + std::to_string(v) + ": " +
                      shown(w) + " is not a finite number");
      }
      ++numbers;
    }
    if (numbers < 3)
      return hinted("line " + std::to_string(line_number) + ": vertex " + std::to_string(v) +
                    " has fewer than 3 coordinates");
    // The keyword's other numbers, as CGAL's scanner takes them (it indexes past the line's
    // numbers when they are missing, and a colour-map index outside an int crashes it).
    const std::size_t h = header.homogeneous ? 1 : 0;
    const std::size_t needed = 3 + h + (header.normals ? 3 + h : 0) + (header.textures ? 2 + h : 0);
    if (numbers < needed)
      return hinted("line " + std::to_string(line_number) + ": vertex " + std::to_string(v) + " has " +
                    plural(numbers, "number") + ", but a vertex of " + header.keyword + " needs " + std::to_string(needed) +
                    " (" + std::to_string(3 + h) + " coordinates" + (header.normals ? ", a normal" : "") +
                    (header.textures ? ", texture coordinates" : "") + ")");
    // Room for a second vertex, and not a face read as a vertex (a corner count k and k
    // indices), which a header counting too many vertices makes (found by review).
    const auto face_shaped = [&] {
      std::int64_t corners = 0, index = 0;
      if (!parseInteger(words[0], corners) || corners < 3 || static_cast<std::uint64_t>(corners) + 1 != numbers)
        return false;
      for (std::size_t k = 1; k < numbers; ++k)
        if (!parseInteger(words[k], index) || index < 0) return false;
      return true;
    };
    if (!header.colors && numbers >= 2 * needed && crowded_line == 0 && !face_shaped()) {
      crowded_line = line_number;
      crowded_numbers = numbers;
      crowded_needed = needed;
    }
    if (header.homogeneous) {  // CGAL divides the coordinates by the fourth number
      double x[4];
      for (std::size_t k = 0; k < 4; ++k) parseDouble(words[k], x[k]);
      if (x[3] == 0 || !std::isfinite(x[0] / x[3]) || !std::isfinite(x[1] / x[3]) || !std::isfinite(x[2] / x[3]))
        return hinted("line " + std::to_string(line_number) + ": vertex " + std::to_string(v) + ": its coordinates divided by its weight " +
                      shown(words[3]) + " (the fourth number of a " + header.keyword + " vertex) are not finite");
    }
    if (header.colors) {
      const std::string problem =
          checkOffColor(words, 3 + h + (header.normals ? 3 + h : 0), numbers - needed, "vertex", vertex_colours);
      if (!problem.empty())
        return hinted("line " + std::to_string(line_number) + ": vertex " + std::to_string(v) + ": " + problem);
    }
  }
  for (std::uint64_t f = 0; f < header.faces; ++f) {
    if (!nextDataLine(in, line, line_number))
      return hinted("the file ends after " + plural(f, "face") + " of the " +
                    std::to_string(header.faces) + " declared");
    const auto words = splitWords(line);
    const std::string where = "line " + std::to_string(line_number) + ": face " +
                              std::to_string(f);
    std::int64_t corners = 0;
    if (!parseInteger(words[0], corners) || corners < 0) {
      if (isHugeInteger(words[0]) && words[0][0] != '-')
        return hinted(where + ": corner count " + shown(words[0]) + " is out of range");
      return hinted(where + ": " + shown(words[0]) + " is not a corner count");
    }
    if (static_cast<std::uint64_t>(corners) + 1 > words.size())
      return hinted(where + " declares " + std::to_string(corners) + " corners but lists " +
                    plural(words.size() - 1, "index"));
    for (std::int64_t k = 1; k <= corners; ++k) {
      std::int64_t index = 0;
      if (!parseInteger(words[k], index)) {
        if (isHugeInteger(words[k]))
          return hinted(where + " uses vertex " + shown(words[k]) + " but the file has " + plural(header.vertices, "vertex"));
        double value;
        if (parseDouble(words[k], value) == NumberStatus::kOk)
          return hinted(where + ": index " + shown(words[k]) + " is not an integer");
        return hinted(where + ": index " + shown(words[k]) + " is not a number");
      }
      if (index < 0 || static_cast<std::uint64_t>(index) >= header.vertices)
        return hinted(where + " uses vertex " + std::string(words[k]) + " but the file has " +
                      plural(header.vertices, "vertex"));
    }
    if (header.colors) {
      const std::size_t first = static_cast<std::size_t>(corners) + 1;
      std::size_t end = first;
      double value;
      while (end < words.size() && parseDouble(words[end], value) == NumberStatus::kOk) ++end;
      const std::string problem = checkOffColor(words, first, end - first, "face", face_colours);
      if (!problem.empty()) return hinted(where + ": " + problem);
    }
  }
  if (nextDataLine(in, line, line_number)) {
    // A DOS end-of-file byte (0x1A) as the file's last word is not data: old exporters wrote one.
    const std::uint64_t extra_line = line_number;
    const bool end_of_file_byte = line.find_first_not_of(" \t\r\v\f\x1a") == std::string::npos &&
                                  std::count(line.begin(), line.end(), '\x1a') == 1;
    if (!end_of_file_byte || nextDataLine(in, line, line_number))
      return hinted("line " + std::to_string(end_of_file_byte ? line_number : extra_line) + ": more data after the " +
                    plural(header.faces, "face") + " the header declares (a wrong face count?)");
  }
  return {};
}

// ---------------------------------------------------------------------------------------------
// OBJ.

// Checks an OBJ file's faces more strictly than CGAL's read_OBJ, which reads a corner as the
// integer its token starts with and skips to the next space (so '2.5', '3abc' or a trailing
// word pass, and a tab glues two corners), takes index 0 for the vertex after the ones read so
// far, and allows an index one past the last vertex. Here every corner must be 'v', 'v/t',
// 'v//n' or 'v/t/n' with integers, v in 1..(vertices in the file) or -1..-(vertices so far).
// Returns the first problem ("line L: ..."), or an empty string.
// The statements CGAL's read_OBJ knows (it fails on any other).
bool knownObjStatement(std::string_view word) {
  static const char* const kKnown[] = {
      "v", "vt", "vn", "f", "l", "vp", "bevel", "lod", "ctech", "c_interp", "usemap", "usemtl",
      "stech", "d_interp", "mtllib", "shadow_obj", "trace_obj", "o", "g", "s", "p", "cstype",
      "deg", "step", "bmat", "con", "curv", "curv2", "surf", "parm", "trim", "hole", "scrv", "sp",
      "end", "surf_1", "q0_1", "q1_1", "curv2d_1", "surf_2", "q0_2", "q1_2", "curv2d_2", "bsp",
      "bzp", "cdc", "cdp", "res"};
  return std::find(std::begin(kKnown), std::end(kKnown), word) != std::end(kKnown);
}

std::string checkObjFaces(const std::string& text) {
  std::uint64_t vertices = 0, faces = 0;
  for (int pass = 1; pass <= 2; ++pass) {
    std::istringstream in(text);
    std::string line;
    std::uint64_t line_number = 0, face = 0, so_far = 0;
    while (nextDataLine(in, line, line_number)) {
      // A CR inside a line: one CR-ended line among LF-ended ones, which CGAL's reader would
      // take for one line, dropping what follows the CR (found by an audit: 'v 1 0 0\rv 5 5 5'
      // lost a vertex).
      const std::size_t cr = line.find('\r');
      if (pass == 1 && cr != std::string::npos && line.find_first_not_of("\r ", cr) != std::string::npos)
        return "line " + std::to_string(line_number) +
               ": a CR inside the line (lines that end in CR alone among LF ones): convert them to LF or CRLF";
      const auto words = splitWords(line);
      // A statement CGAL does not know is reported at its line, before any face that needs the
      // vertices after it (found by an audit: 'V 0 0 0' on line 1 was named as a face's index
      // out of range on line 4).
      if (pass == 1 && !knownObjStatement(words[0]))
        return "line " + std::to_string(line_number) + ": unsupported OBJ statement " + shown(words[0]);
      if (words[0] == "v") {
        // CGAL reads coordinates with operator>>, which stops inside a word ('1-5' is 1 and
        // -5, '3abc' is 3): each of the first three must be a number, whole.
        if (pass == 1)
          for (std::size_t k = 1; k <= 3; ++k) {
            double value;
            if (k < words.size() && parseDouble(words[k], value) == NumberStatus::kOk) continue;
            const std::string at = "line " + std::to_string(line_number) + ": vertex " + std::to_string(so_far);
            if (k >= words.size()) return at + " has fewer than 3 coordinates";
            return at + ": " + shown(words[k]) + " is not a finite number";
          }
        ++so_far;
        continue;
      }
      if (pass == 1 || words[0] != "f") continue;
      const std::string at = "line " + std::to_string(line_number) + ": face " + std::to_string(face);
      for (std::size_t k = 1; k < words.size(); ++k) {
        const std::string_view corner = words[k];
        const std::size_t slash = corner.find('/');
        std::int64_t i = 0;
        const std::string_view vertex = corner.substr(0, slash);
        bool ok = parseInteger(vertex, i);
        if (!ok && isHugeInteger(vertex))
          return at + " uses OBJ index " + shown(vertex) + ", out of range (the file has " + plural(vertices, "vertex") + ")";
        if (ok && slash != std::string_view::npos) {  // '/t', '//n' or '/t/n' after the vertex
          const std::string_view rest = corner.substr(slash + 1);
          const std::size_t second = rest.find('/');
          std::int64_t unused = 0;
          const std::string_view texture = rest.substr(0, second);
          ok = texture.empty() ? second != std::string_view::npos : parseInteger(texture, unused);
          if (!ok && isHugeInteger(texture))
            return at + ": " + shown(corner) + " has a texture index out of range (" + shown(texture) + ")";
          if (ok && second != std::string_view::npos) {
            const std::string_view normal = rest.substr(second + 1);
            ok = parseInteger(normal, unused);
            if (!ok && isHugeInteger(normal))
              return at + ": " + shown(corner) + " has a normal index out of range (" + shown(normal) + ")";
          }
        }
        if (!ok) return at + ": " + shown(corner) + " is not a vertex index ('v', 'v/t', 'v//n' or 'v/t/n')";
        if (i == 0) return at + ": OBJ index 0 is not valid (indices start at 1)";
        if (i > 0 && static_cast<std::uint64_t>(i) > vertices)
          return at + " uses OBJ index " + std::to_string(i) + " but the file has " + plural(vertices, "vertex");
        if (i < 0 && static_cast<std::uint64_t>(-(i + 1)) + 1 > so_far)
          return at + " uses OBJ index " + std::to_string(i) + " but only " + plural(so_far, "vertex") +
                 " precede it";
      }
      ++face;
    }
    vertices = so_far;
    faces = face;
  }
  // CGAL's reader refuses a file without both.
  if (vertices == 0) return "the OBJ file has no vertices ('v' lines)";
  if (faces == 0) return "the OBJ file has no faces ('f' lines)";
  return {};
}

// Appends the k - 2 triangles of one polygon face (corners as a ring, changed here). When the
// fan (c0,c1,c2), (c0,c2,c3), ... is right (each of its triangles turns the polygon's way
// about its Newell normal: c0 sees the whole polygon, as in any convex one) it is the
// triangulation, in that documented order. Otherwise the polygon is cut into ears in the plane
// of its Newell normal, so a planar polygon is covered exactly (that fan would cover area
// outside it). A polygon with no ear to cut (self-intersecting, far from planar) has no one
// right answer: the rest is fanned. Ear cutting is quadratic to cubic in the corners, so it is
// bounded twice: a non-convex polygon of more than kMaxEarCorners corners is fanned whole, and
// the whole file's ear cutting spends at most `ear_work_left` corner tests (EarWork): the
// polygon during which it runs out, and every non-convex polygon after it, are fanned whole
// (found by review: 12 stars of 8192 corners took a minute).
constexpr std::size_t kMaxEarCorners = 8192;

// The ear-cutting budget of one file, in corner tests (one candidate ear looked at, or one
// corner tested against it): kEarWorkBase + kEarWorkPerCorner * (corners of all its faces).
// An ordinary non-convex polygon of k corners takes about k * k / 2; a corner test takes a few
// nanoseconds, so the base is well under a second.
constexpr std::uint64_t kEarWorkBase = std::uint64_t(1) << 26;
constexpr std::uint64_t kEarWorkPerCorner = 256;

void triangulatePolygon(const std::vector<Vec3>& x, std::vector<VertexIndex>& ring, std::vector<Triangle>& out,
                        std::uint64_t& ear_work_left) {
  const std::size_t k = ring.size();
  auto fan = [&] {
    for (std::size_t j = 1; j + 1 < ring.size(); ++j) out.push_back({ring[0], ring[j], ring[j + 1]});
  };
  if (k == 3) return fan();
  const Vec3& origin = x[ring[0]];
  Vec3 normal = Vec3::Zero();  // Newell: twice the polygon's vector area
  for (std::size_t i = 0; i < k; ++i) normal += (x[ring[i]] - origin).cross(x[ring[(i + 1) % k]] - origin);
  auto turn = [&](VertexIndex a, VertexIndex b, VertexIndex c) { return (x[b] - x[a]).cross(x[c] - x[b]).dot(normal); };
  // The fan is right when every one of its triangles turns the polygon's way (c0 sees the
  // whole polygon: convex ones, and many others).
  bool fan_ok = true;
  for (std::size_t j = 1; j + 1 < k && fan_ok; ++j) fan_ok = !(turn(ring[0], ring[j], ring[j + 1]) < 0);
  if (fan_ok || !(normal.squaredNorm() > 0) || k > kMaxEarCorners || ear_work_left == 0) return fan();
  auto inside = [&](VertexIndex q, VertexIndex a, VertexIndex b, VertexIndex c) {  // closed triangle, along the normal
    return turn(a, b, q) >= 0 && turn(b, c, q) >= 0 && turn(c, a, q) >= 0;
  };
  // A corner at the position of one of the ear's (a pinched polygon) blocks it only when one of
  // its edges enters the ear: its other end strictly inside the ear's angle at that corner.
  auto left = [&](VertexIndex p0, VertexIndex p1, VertexIndex q) {
    return (x[p1] - x[p0]).cross(x[q] - x[p0]).dot(normal) > 0;
  };
  auto enters = [&](VertexIndex end, VertexIndex a, VertexIndex b, VertexIndex c, const Vec3& at) {
    if (at == x[a]) return left(c, a, end) && left(a, b, end);
    if (at == x[b]) return left(a, b, end) && left(b, c, end);
    return left(b, c, end) && left(c, a, end);
  };
  // The signed area (times |normal|, twice) the ring still encloses.
  auto enclosed = [&] {
    const Vec3& o = x[ring[0]];
    Vec3 sum = Vec3::Zero();
    for (std::size_t i = 1; i + 1 < ring.size(); ++i) sum += (x[ring[i]] - o).cross(x[ring[i + 1]] - o);
    return sum.dot(normal);
  };
  // Charges `work` corner tests to the file's budget; false when it ran out. Every test below
  // is charged: a self-crossing ring (a figure eight, whose lobes turn opposite ways) encloses
  // nothing long before it is cut down, and each ear's area and spike checks then cost a pass
  // over the ring (found by an audit: one 8000-corner figure eight took 30 s to read).
  auto charge = [&](std::uint64_t work) {
    if (work >= ear_work_left) {
      ear_work_left = 0;
      return false;
    }
    ear_work_left -= work;
    return true;
  };
  // Whether the ring's distinct edges fit in its ring.size() - 2 triangles; if so, appends them
  // as degenerate triangles. `over` is set (and false returned) if the budget runs out.
  auto spikes = [&](bool& over) {
    std::vector<std::pair<VertexIndex, VertexIndex>> edges;
    const std::size_t n = ring.size();
    for (std::size_t i = 0; i < n; ++i) {
      const VertexIndex p = ring[i], q = ring[(i + 1) % n];
      if (x[p] == x[q]) continue;
      if (!charge(edges.size() + 1)) {
        over = true;
        return false;
      }
      const bool seen = std::any_of(edges.begin(), edges.end(), [&](const auto& e) {
        return (x[e.first] == x[p] && x[e.second] == x[q]) || (x[e.first] == x[q] && x[e.second] == x[p]);
      });
      if (!seen) edges.emplace_back(p, q);
      if (edges.size() > n - 2) return false;
    }
    if (edges.empty()) edges.emplace_back(ring[0], ring[1]);  // every corner at one position
    for (std::size_t t = 0; t < n - 2; ++t) {
      const auto& e = edges[std::min(t, edges.size() - 1)];
      out.push_back({e.first, e.second, e.second});
    }
    return true;
  };
  // Kept to fan the polygon whole if the budget runs out.
  const std::vector<VertexIndex> corners = ring;
  const std::size_t first_triangle = out.size();
  auto fanWhole = [&] {
    out.resize(first_triangle);
    ring = corners;
    fan();
  };
  std::size_t from = 0;  // the search resumes next to the last ear: near-quadratic in all
  double area = enclosed();
  while (ring.size() > 3) {
    const std::size_t n = ring.size();
    // A ring that encloses nothing more is what a pinched polygon leaves: spikes, each edge
    // traversed both ways, along the ears' edges or slits of the polygon. Any ear or fan
    // triangle cut from it would cover area outside the polygon: its edges become degenerate
    // triangles instead (k - 2 still, the last repeated).
    // The enclosed area is kept as ears are cut (each takes its own) and taken from the whole
    // ring again only near zero, where it decides (a pass charged to the budget).
    if (!(area > 1e-9 * normal.squaredNorm())) {
      if (!charge(n)) return fanWhole();
      area = enclosed();
      if (!(area > 1e-12 * normal.squaredNorm())) {
        bool over = false;
        if (spikes(over)) return;
        if (over) return fanWhole();
      }
    }
    bool cut = false;
    for (std::size_t step = 0; step < n && !cut; ++step) {
      const std::size_t i = (from + step) % n;
      const VertexIndex a = ring[(i + n - 1) % n], b = ring[i], c = ring[(i + 1) % n];
      std::uint64_t work = 1;
      bool empty = turn(a, b, c) > 0;  // reflex or flat: not an ear
      for (std::size_t j = 0; j < n && empty; ++j, ++work) {
        const VertexIndex q = ring[j];
        const Vec3& at = x[q];
        if (at != x[a] && at != x[b] && at != x[c]) {
          empty = !inside(q, a, b, c);
        } else if (j != (i + n - 1) % n && j != i && j != (i + 1) % n) {
          empty = !enters(ring[(j + n - 1) % n], a, b, c, at) && !enters(ring[(j + 1) % n], a, b, c, at);
        }
      }
      if (!charge(work)) return fanWhole();
      if (!empty) continue;
      out.push_back({a, b, c});
      area -= (x[b] - x[a]).cross(x[c] - x[a]).dot(normal);
      ring.erase(ring.begin() + static_cast<std::ptrdiff_t>(i));
      from = i == 0 ? 0 : i - 1;
      cut = true;
    }
    if (!cut) break;
  }
  fan();
}

// ---------------------------------------------------------------------------------------------
// PLY.

struct PlyType {
  int bytes = 0;  // 0: not a PLY type
  bool integer = false;
  bool is_signed = false;
};

PlyType plyType(std::string_view name) {
  if (name == "char" || name == "int8") return {1, true, true};
  if (name == "uchar" || name == "uint8") return {1, true, false};
  if (name == "short" || name == "int16") return {2, true, true};
  if (name == "ushort" || name == "uint16") return {2, true, false};
  if (name == "int" || name == "int32") return {4, true, true};
  if (name == "uint" || name == "uint32") return {4, true, false};
  if (name == "float" || name == "float32") return {4, false, true};
  if (name == "double" || name == "float64") return {8, false, true};
  return {};
}

struct PlyProperty {
  std::string name;
  std::string type_name;
  PlyType type;        // scalar type, or the item type of a list
  bool list = false;
  PlyType count_type;  // lists only
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;

  const PlyProperty* find(std::string_view property) const {
    for (const PlyProperty& p : properties)
      if (p.name == property) return &p;
    return nullptr;
  }
};

enum class PlyFormat { kAscii, kLittleEndian, kBigEndian };

struct PlyHeader {
  PlyFormat format = PlyFormat::kAscii;
  std::vector<PlyElement> elements;
  std::uint64_t body_offset = 0;
};

bool isVertexElement(const std::string& name) { return name == "vertex" || name == "vertices"; }
bool isFaceElement(const std::string& name) { return name == "face" || name == "faces"; }

// The property a face element's corners are read from: 'vertex_indices', else 'vertex_index'
// (CGAL's order), or null.
const PlyProperty* plyIndexList(const PlyElement& face) {
  const PlyProperty* p = face.find("vertex_indices");
  return p != nullptr ? p : face.find("vertex_index");
}

// Parses a PLY header and checks that CGAL 5.5's reader can read the elements it interprets,
// given the types it misreads re-encoded (reencodePly).
PlyHeader parsePlyHeader(const std::string& path, std::istream& in) {
  PlyHeader header;
  std::string line;
  std::uint64_t line_number = 0;
  bool ended = false;
  std::uint64_t header_bytes = 0;  // read so far
  while (!ended && std::getline(in, line)) {
    ++line_number;
    const bool last_line = in.eof();  // no line break after it
    header_bytes += line.size() + (last_line ? 0 : 1);
    if (header_bytes > kMaxPlyHeaderBytes)
      fail(path, "no PLY end_header in the first " + std::to_string(kMaxPlyHeaderBytes) +
                     " bytes");
    const auto words = splitWords(line);
    // A header cut inside a line (found by review: it was said to have no end_header in the
    // first MiB).
    const bool ply_line = line_number == 1 && words.size() == 1 && words[0] == "ply";
    if (last_line && (line_number > 1 || ply_line) && !(words.size() == 1 && words[0] == "end_header"))
      fail(path, "the PLY header has no end_header (the file ends inside header line " +
                     std::to_string(line_number) + ": truncated file?)");
    const std::string at = "PLY header line " + std::to_string(line_number) + ": ";
    if (line_number == 1) {
      if (words.size() != 1 || words[0] != "ply") fail(path, "not a PLY file (no 'ply' line)");
      continue;
    }
    if (line_number == 2) {  // CGAL wants the format on the second line
      if (words.size() != 3 || words[0] != "format") fail(path, at + "expected 'format ...'");
      if (words[1] == "ascii") header.format = PlyFormat::kAscii;
      else if (words[1] == "binary_little_endian") header.format = PlyFormat::kLittleEndian;
      else if (words[1] == "binary_big_endian") header.format = PlyFormat::kBigEndian;
      else fail(path, at + "unknown format " + shown(words[1]));
      continue;
    }
    if (words.empty()) fail(path, at + "empty line");
    if (words[0] == "comment" || words[0] == "obj_info") continue;
    if (words[0] == "end_header") {
      ended = true;
    } else if (words[0] == "element") {
      std::int64_t count = -1;
      if (words.size() == 3 && isHugeInteger(words[2]) && words[2][0] != '-' && !parseInteger(words[2], count))
        fail(path, at + "element " + shown(words[1]) + " count " + shown(words[2]) + " is out of range");
      if (words.size() != 3 || !parseInteger(words[2], count) || count < 0)
        fail(path, at + "expected 'element NAME COUNT'");
      header.elements.push_back({std::string(words[1]), static_cast<std::uint64_t>(count), {}});
    } else if (words[0] == "property") {
      if (header.elements.empty()) fail(path, at + "property before any element");
      PlyProperty property;
      if (words.size() == 5 && words[1] == "list") {
        property.list = true;
        property.count_type = plyType(words[2]);
        property.type = plyType(words[3]);
        property.type_name = words[3];
        property.name = words[4];
        if (!property.count_type.integer)
          fail(path, at + "list length type " + shown(words[2]) + " is not an integer type");
        if (property.type.bytes == 0) fail(path, at + "unknown type " + shown(words[3]));
      } else if (words.size() == 3) {
        property.type = plyType(words[1]);
        property.type_name = words[1];
        property.name = words[2];
        if (property.type.bytes == 0) fail(path, at + "unknown type " + shown(words[1]));
      } else {
        fail(path, at + "expected 'property TYPE NAME' or 'property list TYPE TYPE NAME'");
      }
      // CGAL would take one of two properties of one name and ignore the other (found by review).
      for (const PlyProperty& other : header.elements.back().properties)
        if (other.name == property.name)
          fail(path, at + "property " + shown(property.name) + " declared twice in element '" +
                         header.elements.back().name + "'");
      header.elements.back().properties.push_back(property);
    } else {
      fail(path, at + "unexpected " + shown(words[0]));
    }
  }
  if (!ended)
    fail(path, line_number < 2 ? "not a PLY file" : "the PLY header has no end_header (truncated file?)");
  header.body_offset = header_bytes;

  // What CGAL's read_PLY interprets, and the types it assumes for it.
  bool has_vertices = false, has_faces = false;
  const PlyElement* vertex_element = nullptr;
  const PlyElement* face_element = nullptr;
  for (const PlyElement& element : header.elements) {
    const std::string what = "PLY element '" + element.name + "'";
    // Two vertex (or face) elements are read one after the other by CGAL, and a face list under
    // both names by one of them: which is meant is not said, so neither is guessed (found by an
    // audit).
    // (An element of no items reads nothing and is let be.)
    const PlyElement*& first = isVertexElement(element.name) ? vertex_element : face_element;
    if ((isVertexElement(element.name) || isFaceElement(element.name)) && element.count > 0) {
      if (first != nullptr)
        fail(path, what + " follows element '" + first->name + "': a PLY file with two " +
                       (isVertexElement(element.name) ? "vertex" : "face") + " elements is ambiguous");
      first = &element;
    }
    if (isFaceElement(element.name) && element.count > 0 && element.find("vertex_indices") != nullptr &&
        element.find("vertex_index") != nullptr)
      fail(path, what + " has both 'vertex_indices' and 'vertex_index' lists: which holds the corners is ambiguous");
    if (element.properties.empty() && element.count > 0) fail(path, what + " has no properties");
    if (isVertexElement(element.name) || isFaceElement(element.name)) {
      // CGAL reads colours when each of red/r, green/g and blue/b is a uchar, then the three of
      // red, green and blue if red is one, else r, g and b, each cast to uchar: another type
      // under one of those names crashed it (found by review).
      auto uchar = [&](const char* name) {
        const PlyProperty* p = element.find(name);
        return p != nullptr && !p->list && p->type.bytes == 1 && p->type.integer && !p->type.is_signed;
      };
      if ((uchar("red") || uchar("r")) && (uchar("green") || uchar("g")) && (uchar("blue") || uchar("b"))) {
        const bool long_names = uchar("red");
        for (const char* name : long_names ? std::array{"red", "green", "blue"} : std::array{"r", "g", "b"}) {
          const PlyProperty* p = element.find(name);
          if (p != nullptr && !uchar(name))
            fail(path, what + ": colour property '" + name + "' is " + (p->list ? "a list" : p->type_name) +
                           ", but the others make it read as uchar (make '" + (long_names ? "red', 'green', 'blue'" : "r', 'g', 'b'") +
                           " all uchar, or rename it)");
        }
      }
    }
    if (isVertexElement(element.name)) {
      has_vertices = true;
      for (const char* axis : {"x", "y", "z"}) {
        const PlyProperty* p = element.find(axis);
        if (p == nullptr) fail(path, what + " has no '" + axis + "' property");
        // Any number type: integers are re-encoded as double for CGAL (reencodePly).
        if (p->list) fail(path, what + ": '" + axis + "' is a list, not a coordinate");
      }
    } else if (isFaceElement(element.name)) {
      has_faces = has_faces || element.count > 0;
      // Any integer item type: items of 1 or 2 bytes are re-encoded as int or uint for CGAL.
      const PlyProperty* p = plyIndexList(element);
      if (p == nullptr || !p->list || !p->type.integer)
        fail(path, what + " needs a 'vertex_indices' list of integers" +
                       (p == nullptr ? std::string()
                                     : " ('" + p->name + "' is " + (p->list ? "a list of " : "") + p->type_name + ")"));
    } else if (element.name == "halfedge") {
      for (const char* end : {"source", "target"}) {
        const PlyProperty* p = element.find(end);
        if (p != nullptr && (p->list || p->type.bytes != 4 || !p->type.integer || p->type.is_signed))
          fail(path, what + ": '" + end + "' must be uint");
      }
    }
  }
  if (!has_vertices) fail(path, "the PLY file has no vertex element");
  if (!has_faces) fail(path, "the PLY file declares no faces");
  return header;
}

std::string plyItem(const PlyElement& element, std::uint64_t item) {
  return "PLY element '" + element.name + "' item " + std::to_string(item);
}

// Walks a binary PLY body: every list length must fit in the bytes left.
void walkBinaryPly(const std::string& path, std::istream& in, const PlyHeader& header,
                   std::uint64_t file_size) {
  std::uint64_t position = header.body_offset;
  const bool big_endian = header.format == PlyFormat::kBigEndian;
  const auto truncated = [&](const PlyElement& element, std::uint64_t item) {
    fail(path, "the file ends inside " + plyItem(element, item) + " (truncated file)");
  };
  for (const PlyElement& element : header.elements) {
    if (element.count == 0) continue;
    std::uint64_t fixed_bytes = 0;  // per item, when there are no lists
    bool has_list = false;
    for (const PlyProperty& p : element.properties) {
      has_list = has_list || p.list;
      fixed_bytes += static_cast<std::uint64_t>(p.list ? p.count_type.bytes : p.type.bytes);
    }
    const std::uint64_t left = file_size - position;
    if (element.count > left / fixed_bytes) {
      fail(path, "PLY element '" + element.name + "' declares " + std::to_string(element.count) +
                     " items of at least " + std::to_string(fixed_bytes) + " bytes, but only " +
                     std::to_string(left) + " bytes are left (truncated file or wrong count)");
    }
    if (!has_list) {
      position += element.count * fixed_bytes;
      in.seekg(static_cast<std::streamoff>(position));
      continue;
    }
    for (std::uint64_t item = 0; item < element.count; ++item) {
      for (const PlyProperty& p : element.properties) {
        if (!p.list) {
          if (file_size - position < static_cast<std::uint64_t>(p.type.bytes))
            truncated(element, item);
          in.ignore(p.type.bytes);
          position += static_cast<std::uint64_t>(p.type.bytes);
          continue;
        }
        const int n = p.count_type.bytes;
        unsigned char bytes[4] = {0, 0, 0, 0};
        if (file_size - position < static_cast<std::uint64_t>(n) ||
            !in.read(reinterpret_cast<char*>(bytes), n))
          truncated(element, item);
        position += static_cast<std::uint64_t>(n);
        std::uint64_t raw = 0;
        for (int b = 0; b < n; ++b) raw |= std::uint64_t(bytes[big_endian ? n - 1 - b : b]) << (8 * b);
        const bool negative = p.count_type.is_signed && (raw >> (8 * n - 1)) != 0;
        if (negative)
          fail(path, plyItem(element, item) + ": negative list length for '" + p.name + "'");
        const std::uint64_t bytes_needed = raw * static_cast<std::uint64_t>(p.type.bytes);
        if (bytes_needed > file_size - position)
          fail(path, plyItem(element, item) + ": list '" + p.name + "' declares " +
                         std::to_string(raw) + " entries but the file ends first");
        in.ignore(static_cast<std::streamsize>(bytes_needed));
        position += bytes_needed;
      }
    }
    in.seekg(static_cast<std::streamoff>(position));
  }
  if (position < file_size) {
    // A few blank bytes (a final newline) are tolerated; anything else is refused.
    constexpr std::uint64_t kBlankTail = 16;
    bool blank = file_size - position <= kBlankTail;
    if (blank) {
      char tail[kBlankTail];
      in.clear();
      in.seekg(static_cast<std::streamoff>(position));
      in.read(tail, static_cast<std::streamsize>(file_size - position));
      for (std::streamsize k = 0; k < in.gcount(); ++k) blank &= std::isspace(static_cast<unsigned char>(tail[k])) != 0;
    }
    if (!blank)
      fail(path, std::to_string(file_size - position) + " bytes follow the last element the header declares "
                 "(wrong counts or extra data)");
  }
}

// Reads the next whitespace-separated word of an ASCII PLY body; false at the end.
bool nextPlyWord(std::streambuf& buffer, std::string& word) {
  constexpr std::size_t kMaxWord = std::size_t(1) << 16;
  word.clear();
  int c;
  while ((c = buffer.sgetc()) != EOF && std::isspace(c)) buffer.sbumpc();
  bool cut = false;
  while ((c = buffer.sgetc()) != EOF && !std::isspace(c)) {
    // The whole word is consumed (a number written with 600 digits is one value; cutting it
    // at 512 read its end as the next value, found by review); beyond 64 KiB only its start is
    // kept, and it is reported as not a number.
    if (word.size() < kMaxWord) word += static_cast<char>(c);
    else cut = true;
    buffer.sbumpc();
  }
  if (cut) word = "<a value over 65536 characters>";
  return !word.empty();
}

// Checks that an ASCII PLY word is a value of the given type (integers in range, finite floats).
std::string checkPlyValue(std::string_view word, const PlyType& type, std::int64_t& integer) {
  if (type.integer) {
    if (!parseInteger(word, integer))
      return shown(word) + (isHugeInteger(word) ? " is out of range for its type" : " is not an integer");
    const std::int64_t max = type.is_signed ? (std::int64_t(1) << (8 * type.bytes - 1)) - 1
                                            : (std::int64_t(1) << (8 * type.bytes)) - 1;
    const std::int64_t min = type.is_signed ? -max - 1 : 0;
    if (integer < min || integer > max) return shown(word) + " is out of range for its type";
    return {};
  }
  double value;
  switch (parseDouble(word, value)) {
    case NumberStatus::kOk:
      if (type.bytes == 4 && std::isinf(static_cast<float>(value)))
        return shown(word) + " is too large for a float";
      return {};
    case NumberStatus::kNonFinite: return shown(word) + " is not finite";
    case NumberStatus::kNotANumber: break;
  }
  return shown(word) + " is not a number";
}

// Walks an ASCII PLY body: every word must be a number of its declared type, every list length
// must fit in the words left.
void walkAsciiPly(const std::string& path, std::istream& in, const PlyHeader& header,
                  std::uint64_t file_size) {
  std::uint64_t left = file_size - header.body_offset;  // upper bound on the bytes still unread
  for (const PlyElement& element : header.elements) {
    if (element.count == 0) continue;
    // Every value takes at least two bytes ("0 "), the very last one at least one.
    const std::uint64_t min_bytes = 2 * element.properties.size();
    if (element.count > (left + 1) / min_bytes) {
      fail(path, "PLY element '" + element.name + "' declares " + std::to_string(element.count) +
                     " items but only " + std::to_string(left) +
                     " bytes are left (truncated file or wrong count)");
    }
    left -= std::min(left, element.count * min_bytes);
  }
  std::streambuf& buffer = *in.rdbuf();
  std::string word;
  std::int64_t integer = 0;
  const std::uint64_t body = file_size - header.body_offset;
  for (const PlyElement& element : header.elements) {
    for (std::uint64_t item = 0; item < element.count; ++item) {
      for (const PlyProperty& p : element.properties) {
        const auto next = [&](const PlyType& type) {
          if (!nextPlyWord(buffer, word))
            fail(path, "the file ends inside " + plyItem(element, item) + " (truncated file)");
          const std::string problem = checkPlyValue(word, type, integer);
          if (!problem.empty()) fail(path, plyItem(element, item) + ", '" + p.name + "': " + problem);
        };
        if (!p.list) {
          next(p.type);
          continue;
        }
        next(p.count_type);
        if (integer < 0)
          fail(path, plyItem(element, item) + ": negative list length for '" + p.name + "'");
        if (static_cast<std::uint64_t>(integer) > body)
          fail(path, plyItem(element, item) + ": list '" + p.name + "' declares " +
                         std::to_string(integer) + " entries but the file ends first");
        for (std::int64_t k = integer; k > 0; --k) next(p.type);
      }
    }
  }
  // A DOS end-of-file byte (0x1A) as the file's last word is not data: old exporters wrote one.
  if (nextPlyWord(buffer, word) && (word != "\x1a" || nextPlyWord(buffer, word)))
    fail(path, "more data (" + shown(word) + ") after the last element the header declares (wrong counts?)");
}

// ---------------------------------------------------------------------------------------------
// PLY re-encoded for CGAL.

// The type CGAL 5.5 is given for a property: its own, except a vertex coordinate of an integer
// type (double: CGAL reads x, y and z only as float or double) and the items of a face's index
// list of 1 or 2 bytes (int or uint by signedness: CGAL reads indices only as those). Each
// value of the file's type is exact in the one given.
PlyType plyTypeForCgal(const PlyElement& element, const PlyProperty& p) {
  if (isVertexElement(element.name) && !p.list && p.type.integer && (p.name == "x" || p.name == "y" || p.name == "z"))
    return {8, false, true};
  if (isFaceElement(element.name) && p.list && p.type.integer && p.type.bytes < 4 && &p == plyIndexList(element))
    return {4, true, p.type.is_signed};
  return p.type;
}

// Whether a file has a property whose type plyTypeForCgal changes.
bool plyNeedsReencoding(const PlyHeader& header) {
  for (const PlyElement& element : header.elements)
    for (const PlyProperty& p : element.properties)
      if (plyTypeForCgal(element, p).bytes != p.type.bytes) return true;
  return false;
}

const char* plyTypeName(const PlyType& type) {
  if (!type.integer) return type.bytes == 4 ? "float" : "double";
  switch (type.bytes) {
    case 1: return type.is_signed ? "char" : "uchar";
    case 2: return type.is_signed ? "short" : "ushort";
    default: return type.is_signed ? "int" : "uint";
  }
}

// The header CGAL is given with a re-encoded file: the file's elements and properties in order,
// each type by its plain name (plyTypeForCgal's), without comments.
std::string plyHeaderForCgal(const PlyHeader& header) {
  std::string text = "ply\nformat ";
  switch (header.format) {
    case PlyFormat::kAscii: text += "ascii"; break;
    case PlyFormat::kLittleEndian: text += "binary_little_endian"; break;
    case PlyFormat::kBigEndian: text += "binary_big_endian"; break;
  }
  text += " 1.0\n";
  for (const PlyElement& element : header.elements) {
    text += "element " + element.name + " " + std::to_string(element.count) + "\n";
    for (const PlyProperty& p : element.properties) {
      text += "property ";
      if (p.list) text += std::string("list ") + plyTypeName(p.count_type) + " ";
      text += std::string(plyTypeName(plyTypeForCgal(element, p))) + " " + p.name + "\n";
    }
  }
  return text + "end_header\n";
}

// The bits of a binary PLY value of `bytes` bytes (at most 8) in the file's byte order, and back.
std::uint64_t plyBits(const char* data, int bytes, bool big_endian) {
  std::uint64_t bits = 0;
  for (int b = 0; b < bytes; ++b)
    bits |= std::uint64_t(static_cast<unsigned char>(data[big_endian ? bytes - 1 - b : b])) << (8 * b);
  return bits;
}
void putPlyBits(char* data, std::uint64_t bits, int bytes, bool big_endian) {
  for (int b = 0; b < bytes; ++b) data[big_endian ? bytes - 1 - b : b] = static_cast<char>((bits >> (8 * b)) & 0xffu);
}

// The value of a PLY integer (of at most 4 bytes) from its bits.
std::int64_t plyInteger(std::uint64_t bits, const PlyType& type) {
  const int width = 8 * type.bytes;
  if (type.is_signed && (bits >> (width - 1)) != 0) return static_cast<std::int64_t>(bits) - (std::int64_t(1) << width);
  return static_cast<std::int64_t>(bits);
}

// A binary PLY body (the bytes after the header) with the types of plyTypeForCgal, in the file's
// byte order: each changed value converted, every other byte copied as it is (what follows the
// last element too). walkBinaryPly has checked the lengths; each read is bounds-checked all the
// same. With `out` null, only counts the bytes the result takes; returns that count.
std::uint64_t reencodePlyBody(const std::string& path, const PlyHeader& header, std::string_view body,
                              std::string* out) {
  const bool big_endian = header.format == PlyFormat::kBigEndian;
  std::uint64_t at = 0;    // bytes of the body read
  std::uint64_t size = 0;  // bytes of the result
  const std::string changed_file = "read error (the file changed while it was read?)";
  const auto take = [&](std::uint64_t bytes) {
    if (bytes > body.size() - at) fail(path, changed_file);
    const char* data = body.data() + at;
    at += bytes;
    return data;
  };
  const auto emit = [&](const char* data, std::uint64_t bytes) {
    if (out != nullptr) out->append(data, bytes);
    size += bytes;
  };
  std::vector<PlyType> types;  // CGAL's, per property
  for (const PlyElement& element : header.elements) {
    if (element.count == 0) continue;
    types.clear();
    bool changed = false, has_list = false;
    std::uint64_t item_bytes = 0, item_bytes_out = 0;  // an item's, when it has no list
    for (const PlyProperty& p : element.properties) {
      types.push_back(plyTypeForCgal(element, p));
      changed = changed || types.back().bytes != p.type.bytes;
      has_list = has_list || p.list;
      item_bytes += static_cast<std::uint64_t>(p.type.bytes);
      item_bytes_out += static_cast<std::uint64_t>(types.back().bytes);
    }
    // Items of one size: copied whole, or counted from the header's count (the product
    // checked: the count fits in the body).
    if (!has_list && (!changed || out == nullptr)) {
      if (element.count > (body.size() - at) / item_bytes) fail(path, changed_file);
      const char* data = take(element.count * item_bytes);
      if (!changed) {
        emit(data, element.count * item_bytes);
      } else {
        if (element.count > (std::numeric_limits<std::uint64_t>::max() - size) / item_bytes_out)
          fail(path, "too large to re-encode for reading");
        size += element.count * item_bytes_out;
      }
      continue;
    }
    for (std::uint64_t item = 0; item < element.count; ++item) {
      for (std::size_t k = 0; k < element.properties.size(); ++k) {
        const PlyProperty& p = element.properties[k];
        const PlyType& to = types[k];
        std::uint64_t values = 1;  // list items are at most 2^32 - 1
        if (p.list) {
          const char* count = take(static_cast<std::uint64_t>(p.count_type.bytes));
          const std::int64_t length = plyInteger(plyBits(count, p.count_type.bytes, big_endian), p.count_type);
          if (length < 0) fail(path, plyItem(element, item) + ": negative list length for '" + p.name + "'");
          values = static_cast<std::uint64_t>(length);
          emit(count, static_cast<std::uint64_t>(p.count_type.bytes));
        }
        const auto from_bytes = static_cast<std::uint64_t>(p.type.bytes);
        const auto to_bytes = static_cast<std::uint64_t>(to.bytes);
        if (from_bytes == to_bytes || out == nullptr) {
          const char* data = take(values * from_bytes);
          if (from_bytes == to_bytes) emit(data, values * from_bytes);
          else size += values * to_bytes;
          continue;
        }
        for (std::uint64_t v = 0; v < values; ++v) {
          const std::int64_t value = plyInteger(plyBits(take(from_bytes), p.type.bytes, big_endian), p.type);
          char converted[8];
          if (to.integer) {  // int or uint: the same bits for either
            putPlyBits(converted, static_cast<std::uint32_t>(value), 4, big_endian);
          } else {  // double: exact (|value| < 2^32)
            const double d = static_cast<double>(value);
            std::uint64_t bits;
            std::memcpy(&bits, &d, sizeof bits);
            putPlyBits(converted, bits, 8, big_endian);
          }
          emit(converted, to_bytes);
        }
      }
    }
  }
  emit(take(body.size() - at), body.size() - at);
  return size;
}

// The file as CGAL is given it when plyNeedsReencoding: plyHeaderForCgal's header, then the body,
// ASCII as it is (walkAsciiPly has checked that each value is an integer of its type, which CGAL
// reads the same as int, uint or double), binary re-encoded (reencodePlyBody). `in` is the file
// as checked (without its byte order mark), `file_size` its size.
std::string reencodePly(const std::string& path, std::istream& in, const PlyHeader& header,
                        std::uint64_t file_size) {
  const std::string cgal_header = plyHeaderForCgal(header);
  const std::uint64_t body_size = file_size - header.body_offset;
  in.clear();
  in.seekg(static_cast<std::streamoff>(header.body_offset));
  std::string text;
  if (header.format == PlyFormat::kAscii) {
    text.reserve(cgal_header.size() + body_size);
    text += cgal_header;
    text.resize(cgal_header.size() + body_size);
    in.read(text.data() + cgal_header.size(), static_cast<std::streamsize>(body_size));
    if (static_cast<std::uint64_t>(in.gcount()) != body_size) fail(path, "read error");
    return text;
  }
  std::string body(body_size, '\0');
  in.read(body.data(), static_cast<std::streamsize>(body_size));
  if (static_cast<std::uint64_t>(in.gcount()) != body_size) fail(path, "read error");
  const std::uint64_t size = reencodePlyBody(path, header, body, nullptr);
  if (size > text.max_size() - cgal_header.size()) fail(path, "too large to re-encode for reading");
  text.reserve(cgal_header.size() + size);
  text += cgal_header;
  reencodePlyBody(path, header, body, &text);
  return text;
}

// A stream buffer that reads a string in place (std::istringstream's str() copies it).
class StringInput : public std::streambuf {
 public:
  explicit StringInput(std::string text) : text_(std::move(text)) {
    setg(text_.data(), text_.data(), text_.data() + text_.size());
  }

 private:
  std::string text_;
};

// ---------------------------------------------------------------------------------------------
// STL.

std::uint32_t littleEndian32(const unsigned char* bytes) {
  return std::uint32_t(bytes[0]) | std::uint32_t(bytes[1]) << 8 | std::uint32_t(bytes[2]) << 16 |
         std::uint32_t(bytes[3]) << 24;
}

// An ASCII STL's words in order: 'solid' [name], then per facet 'facet' ['normal' x y z]
// 'outer' 'loop' 3 x ('vertex' x y z) 'endloop' 'endfacet', then 'endsolid' [name]; several
// solids may follow one another; after an 'endsolid', a first word that is not 'solid' ends the
// data. CGAL's parser skips what it does not expect, and when it fails it retries the file as
// binary, which for a file under 80 bytes succeeds with the facets read so far: a malformed
// facet must be caught here. Returns the first problem, or "" and `text` made what CGAL is to
// read (found by review): cut after the line of the last 'endsolid' (CGAL read a facet after
// it), and each name, the rest of a 'solid' or 'endsolid' line, made blanks (CGAL reads every
// word: a name 'solid' or 'facet' was read as a keyword, and a tab after the first 'solid' made
// it try the file as binary first).
std::string checkAsciiStl(std::string& text) {
  std::uint64_t line_number = 0, facets = 0, solids = 0;
  bool in_solid = false, in_facet = false, in_loop = false;
  int vertices = 0;
  std::size_t data_end = 0;  // after the line of the last 'endsolid'
  bool ended = false;        // a word after an 'endsolid' ended the data
  for (std::size_t line_begin = 0; line_begin < text.size() && !ended;) {
    const std::size_t line_end = std::min(text.find('\n', line_begin), text.size());
    const std::string_view line(text.data() + line_begin, line_end - line_begin);
    const std::size_t next_line = std::min(line_end + 1, text.size());
    ++line_number;
    const auto words = splitWords(line);
    const std::string at = "line " + std::to_string(line_number) + ": ";
    // The rest of the line after word w is a name: blanks for CGAL.
    auto blankName = [&](std::string_view w) {
      std::fill(text.begin() + (w.data() + w.size() - text.data()), text.begin() + line_end, ' ');
    };
    for (std::size_t k = 0; k < words.size(); ++k) {
      const std::string_view w = words[k];
      auto numbers = [&](const char* what) -> std::string {
        if (k + 3 >= words.size()) return at + "'" + what + "' needs 3 numbers";
        for (std::size_t j = k + 1; j <= k + 3; ++j) {
          double value;
          if (parseDouble(words[j], value) != NumberStatus::kOk)
            return at + what + " coordinate " + shown(words[j]) + " is not a finite number";
        }
        k += 3;
        return {};
      };
      if (!in_solid) {
        // After an 'endsolid', what is not another solid is ignored (a DOS end-of-file byte,
        // padding, a trailing line, a stray facet).
        if (w != "solid") {
          if (facets == 0 && solids == 0) return at + "expected 'solid', found " + shown(w);
          ended = true;
          break;
        }
        in_solid = true;
        blankName(w);
        break;
      }
      if (w == "endsolid") {
        if (in_facet) return at + "'endsolid' inside facet " + std::to_string(facets - 1);
        in_solid = false;
        ++solids;
        blankName(w);
        data_end = next_line;
        break;
      }
      if (w == "facet") {
        if (in_facet) return at + "facet " + std::to_string(facets - 1) + " has no 'endfacet'";
        in_facet = true;
        vertices = 0;
        ++facets;
        // A normal's three words are not read (by CGAL either): exporters write 'nan' there for
        // degenerate facets.
        if (k + 1 < words.size() && words[k + 1] == "normal") {
          if (k + 4 >= words.size()) return at + "'normal' needs 3 numbers";
          for (std::size_t j = k + 2; j <= k + 4; ++j)  // CGAL takes a keyword there for one
            for (const char* keyword : {"solid", "endsolid", "facet", "normal", "outer", "loop", "vertex", "endloop", "endfacet"})
              if (words[j] == keyword)
                return at + "the normal of facet " + std::to_string(facets - 1) + " has " + shown(words[j]) +
                       " among its 3 numbers";
          k += 4;
        }
        continue;
      }
      if (!in_facet) return at + "expected 'facet' or 'endsolid', found " + shown(w);
      if (w == "outer" && k + 1 < words.size() && words[k + 1] == "loop") {
        in_loop = true;
        ++k;
      } else if (w == "vertex") {  // 'outer loop' is optional to CGAL, and here
        const std::string problem = numbers("vertex");
        if (!problem.empty()) return problem;
        ++vertices;
      } else if (w == "endloop" && in_loop) {
        in_loop = false;
      } else if (w == "endfacet" && !in_loop) {
        if (vertices != 3)
          return at + "facet " + std::to_string(facets - 1) + " has " + plural(vertices, "vertex") + " (3 needed)";
        in_facet = false;
      } else {
        return at + "unexpected " + shown(w) + " in facet " + std::to_string(facets - 1);
      }
    }
    line_begin = next_line;
  }
  if (in_facet || in_solid) return "the ASCII STL ends inside " + std::string(in_facet ? "a facet" : "its solid") +
                                   " (no 'endsolid': truncated file?)";
  text.resize(data_end);
  return {};
}

// How an STL file's first bytes (header and triangle count) read: ASCII first when, after
// whitespace (from byte `from`), "solid" and a blank or line end start it; as binary, the count
// and the size it needs.
constexpr std::uint64_t kStlHeaderBytes = 84, kStlTriangleBytes = 50;
struct StlStart {
  bool solid = false;
  std::uint64_t triangles = 0;  // the binary count (0 when the file is shorter than its header)
  std::uint64_t needed = 0;     // the size the count needs
  bool binary_size = false;     // the file has exactly that size
};
StlStart readStlStart(const unsigned char* bytes, std::uint64_t got, std::uint64_t file_size, std::uint64_t from = 0) {
  StlStart out;
  got = std::min(got, kStlHeaderBytes);
  std::uint64_t first = from;
  while (first < got && std::isspace(bytes[first])) ++first;
  // CGAL wants a space or a line end after 'solid'; any blank is taken here (found by review: a
  // tab made a valid ASCII file a truncated binary one), and checkAsciiStl makes it a space.
  out.solid = got >= first + 6 && std::memcmp(bytes + first, "solid", 5) == 0 &&
              (bytes[first + 5] == '\n' || isBlank(static_cast<char>(bytes[first + 5])));
  out.triangles = got == kStlHeaderBytes ? littleEndian32(bytes + 80) : 0;
  out.needed = kStlHeaderBytes + kStlTriangleBytes * out.triangles;
  out.binary_size = got == kStlHeaderBytes && out.needed == file_size;
  return out;
}

// Decides ASCII or binary the way CGAL does and checks an ASCII file (checkAsciiStl). A binary
// file is read here: its triangle count must match the file size exactly and its coordinates
// be finite (CGAL merges equal points through a std::map, where NaN compares equal to
// anything); CGAL tries ASCII first when the 80-byte header starts with "solid ", and kept
// facets spelled out in such a header before the file's own. Equal corners are merged into one
// vertex, numbered in order of first use, as CGAL does. Returns true when it read the file;
// false for an ASCII file, then in `ascii_text` as CGAL is to read it (checkAsciiStl).
bool checkStl(const std::string& path, std::istream& in, std::uint64_t file_size,
              std::vector<CgalPoint>& points, std::vector<Corners>& polygons, std::string& ascii_text) {
  unsigned char header[kStlHeaderBytes] = {};
  in.read(reinterpret_cast<char*>(header), kStlHeaderBytes);
  const std::uint64_t got = static_cast<std::uint64_t>(in.gcount());
  const StlStart start = readStlStart(header, got, file_size);
  const bool solid = start.solid, binary_size = start.binary_size;
  const std::uint64_t triangles = start.triangles, needed = start.needed;
  if (solid && !binary_size) {
    // ASCII: CGAL grows its arrays while it reads; the structure is checked here.
    in.clear();
    in.seekg(0);
    ascii_text.assign(std::istreambuf_iterator<char>(in), {});
    if (in.bad()) fail(path, "read error");
    // A control byte no text holds (binary floats have many) after the header: a binary file,
    // whose count asks for more bytes than it has (checked before checkAsciiStl blanks names).
    const bool binary_bytes = std::any_of(ascii_text.begin() + std::min<std::size_t>(ascii_text.size(), kStlHeaderBytes),
                                          ascii_text.end(), [](char c) {
                                            const auto u = static_cast<unsigned char>(c);
                                            return u < 32 && !std::isspace(u) && u != 0x1A;
                                          });
    const std::string problem = checkAsciiStl(ascii_text);
    if (!problem.empty()) {
      // A binary file whose header starts with "solid " and whose size does not match its
      // count is taken for ASCII: say what it would be as binary too.
      if (got == kStlHeaderBytes && needed <= file_size && triangles > 0)
        fail(path, "not a valid ASCII STL (" + problem + "), nor a binary one: its header declares " +
                       plural(triangles, "triangle") + " (" + std::to_string(needed) + " bytes) but the file has " +
                       std::to_string(file_size - needed) + " more bytes");
      if (got == kStlHeaderBytes && triangles > 0 && binary_bytes)
        fail(path, "a binary STL (its header starts with 'solid', but binary data follows): it declares " +
                       plural(triangles, "triangle") + ", which need " + std::to_string(needed) +
                       " bytes, but the file has " + std::to_string(file_size) + " (truncated file)");
      fail(path, problem);
    }
    return false;
  }
  if (got < kStlHeaderBytes)
    fail(path, "not an ASCII STL (no 'solid') and too short for a binary STL (" +
                   std::to_string(file_size) + " bytes; the binary header alone has 84)");
  // 'SOLID' or 'Solid' is no ASCII STL keyword (CGAL reads binary then): say so, not that a
  // binary count of four letters is wrong.
  std::uint64_t first = 0;
  while (first < got && std::isspace(header[first])) ++first;
  if (first + 6 <= got && !binary_size &&
      std::equal(header + first, header + first + 5, "solid", [](unsigned char a, char b) { return std::tolower(a) == b; }) &&
      (header[first + 5] == '\n' || isBlank(static_cast<char>(header[first + 5]))))
    fail(path, "not an ASCII STL: it starts with '" + std::string(reinterpret_cast<const char*>(header + first), 5) +
                   "', and ASCII STL keywords are lowercase ('solid'); nor a binary one (its size does not match "
                   "the count its header would hold)");
  if (needed > file_size)
    fail(path, "the binary STL header declares " + plural(triangles, "triangle") + ", which need " +
                   std::to_string(needed) + " bytes, but the file has " + std::to_string(file_size) +
                   " (truncated file)");
  if (needed < file_size)
    fail(path, "the binary STL header declares " + plural(triangles, "triangle") + " (" +
                   std::to_string(needed) + " bytes) but the file has " + std::to_string(file_size - needed) +
                   " more bytes (a wrong triangle count?)");
  std::map<std::array<float, 3>, std::size_t> index;  // corner -> vertex
  polygons.reserve(static_cast<std::size_t>(triangles));
  unsigned char record[kStlTriangleBytes];
  for (std::uint64_t t = 0; t < triangles; ++t) {
    if (!in.read(reinterpret_cast<char*>(record), kStlTriangleBytes))
      fail(path, "read error in binary STL triangle " + std::to_string(t));
    Corners corners;
    for (int c = 0; c < 3; ++c) {
      std::array<float, 3> x;
      for (int axis = 0; axis < 3; ++axis) {  // the 9 corner coordinates after the normal
        const std::uint32_t bits = littleEndian32(record + 4 * (3 + 3 * c + axis));
        if ((bits & 0x7f800000u) == 0x7f800000u)
          fail(path, "binary STL triangle " + std::to_string(t) + " has a non-finite coordinate");
        float value;
        std::memcpy(&value, &bits, sizeof value);
        x[axis] = value + 0.0f;  // -0 and 0 are one point
      }
      const auto [it, added] = index.emplace(x, points.size());
      if (added) points.emplace_back(x[0], x[1], x[2]);
      corners.push_back(it->second);
    }
    polygons.push_back(std::move(corners));
  }
  return true;
}

// ---------------------------------------------------------------------------------------------

std::string cgalRejected(Format format) {
  switch (format) {
    case Format::kOff:
      return "malformed OFF data (vertex lines need 3 numbers, face lines 'k i1 ... ik' with "
             "indices below the vertex count)";
    case Format::kObj:
      return "malformed OBJ file (a 'v' line without 3 numbers, a statement that OBJ does not "
             "define, or no vertices or faces)";
    case Format::kPly:
      return "malformed PLY data (CGAL's reader stopped before the end)";
    case Format::kStl:
      return "malformed ASCII STL (expected 'facet ... vertex x y z ... endfacet' blocks, 3 "
             "vertices each, closed by 'endsolid')";
  }
  return "malformed file";
}

// What a text file needs before it is read: a UTF-8 byte order mark to drop (Windows editors
// write one), lines ended by CR alone to end with LF (classic Mac OS: the readers split lines on
// LF only). A binary STL (by its size; its 80-byte header may hold any bytes) needs neither, and
// an STL is text only when 'solid' starts it. Leaves `in` at the start.
struct TextRepair {
  bool bom = false;
  bool cr_only = false;
};
TextRepair textRepair(const std::string& path, std::istream& in, Format format, std::uint64_t file_size) {
  constexpr std::size_t kLook = 1 << 16;  // a text file has a line break by then
  std::string start(kLook, '\0');
  in.read(start.data(), kLook);
  start.resize(static_cast<std::size_t>(in.gcount()));
  in.clear();
  in.seekg(0);
  TextRepair repair;
  const bool bom = start.compare(0, kUtf8Bom.size(), kUtf8Bom) == 0;
  if (format == Format::kStl) {
    // Text: 'solid' and a blank first (as checkStl decides, after the mark), no zero byte
    // (binary records nearly always hold one), and a size that is not a binary file's.
    const StlStart stl = readStlStart(reinterpret_cast<const unsigned char*>(start.data()), start.size(), file_size,
                                      bom ? kUtf8Bom.size() : 0);
    if (stl.binary_size || !stl.solid || start.find('\0') != std::string::npos) return repair;
  }
  repair.bom = bom;
  repair.cr_only = start.find('\r') != std::string::npos && start.find('\n') == std::string::npos;
  // A PLY's body may be binary, where a CR is data.
  if (repair.cr_only && format == Format::kPly)
    fail(path, "its lines end in CR alone (classic Mac OS): convert them to LF or CRLF");
  return repair;
}

// The reason of a read error that a stream buffer threw (std::ios_base::failure: a filebuf read
// through sbumpc, not an istream function, throws instead of setting badbit): errno's text.
std::string readError() {
  const int code = errno;
  return std::string("read error (") + (code != 0 ? std::strerror(code) : "I/O error") + ")";
}

Mesh readMeshFrom(const std::string& path) {
  std::ifstream file;
  std::uint64_t file_size = openInput(path, file);
  const Format format = formatOf(path);
  // A text file with a byte order mark or CR line ends is repaired in memory (textRepair).
  std::istringstream repaired;
  const TextRepair repair = textRepair(path, file, format, file_size);
  if (repair.bom || repair.cr_only) {
    file.seekg(repair.bom ? static_cast<std::streamoff>(kUtf8Bom.size()) : 0);
    std::string text(std::istreambuf_iterator<char>(file), {});
    if (file.bad()) fail(path, "read error");
    // CRs alone end lines; a CRLF past the first look (a first line longer than 64 KiB) stays.
    if (repair.cr_only)
      for (size_t i = 0; i < text.size(); ++i)
        if (text[i] == '\r' && (i + 1 == text.size() || text[i + 1] != '\n')) text[i] = '\n';
    file_size = text.size();
    repaired.str(std::move(text));
  }
  std::istream& in = repair.bom || repair.cr_only ? static_cast<std::istream&>(repaired) : file;

  OffHeader off_header;
  // A PLY file with types CGAL 5.5 misreads, re-encoded for it (reencodePly); others go to CGAL
  // as they are.
  bool ply_reencoded = false;
  std::string ply_text;
  switch (format) {
    case Format::kOff:
      off_header = checkOffHeader(path, in, file_size);
      break;
    case Format::kPly: {
      const PlyHeader header = parsePlyHeader(path, in);
      if (header.format == PlyFormat::kAscii) walkAsciiPly(path, in, header, file_size);
      else walkBinaryPly(path, in, header, file_size);
      if (plyNeedsReencoding(header)) {
        try {
          ply_text = reencodePly(path, in, header, file_size);
        } catch (const std::bad_alloc&) {
          fail(path, "out of memory while reading");
        }
        ply_reencoded = true;
      }
      break;
    }
    case Format::kStl:
      break;  // below: a binary file is read by checkStl
    case Format::kObj:
      break;
  }
  std::vector<CgalPoint> points;
  std::vector<Corners> polygons;
  // OBJ and ASCII STL go to CGAL from memory, as checked and prepared here.
  std::istringstream cgal_text;
  std::string stl_text;
  const bool read_here = format == Format::kStl && checkStl(path, in, file_size, points, polygons, stl_text);
  if (format == Format::kStl && !read_here) cgal_text.str(std::move(stl_text));
  // OBJ: blanks made spaces (CGAL's reader splits corners on spaces only), after the strict
  // check of its faces.
  if (format == Format::kObj) {
    std::string text(std::istreambuf_iterator<char>(in), {});
    if (in.bad()) fail(path, "read error");
    for (char& c : text)
      if (isBlank(c) && c != '\r') c = ' ';
    // Every statement ends with a line break, the last too (a bare 'l' there was not found).
    if (!text.empty() && text.back() != '\n') text += '\n';
    // A DOS end-of-file byte (0x1A) alone on the file's last line is not a statement: old
    // exporters wrote one.
    const size_t last = text.find_last_not_of(" \r\n");
    if (last != std::string::npos && text[last] == '\x1a') {
      const size_t before = last == 0 ? std::string::npos : text.find_last_not_of(' ', last - 1);
      if (before == std::string::npos || text[before] == '\n') text[last] = ' ';
    }
    // Each statement of the text: f(first, end), its keyword's first character and its line's
    // end (blanks are spaces by now).
    auto statements = [&text](auto&& f) {
      for (size_t at = 0; at < text.size();) {
        const size_t end = std::min(text.find('\n', at), text.size());
        size_t first = at;
        while (first < end && text[first] == ' ') ++first;
        f(first, end);
        at = end + 1;
      }
    };
    auto keyword = [&text](size_t first, size_t end, char c) {
      return first < end && text[first] == c &&
             ((first + 1 == end && end < text.size()) || text[first + 1] == ' ' || text[first + 1] == '\r');
    };
    // Line elements ('l', polylines of an exporter's loose edges) are not faces, and CGAL's
    // reader refuses them: they become comments (line numbers kept). A '#' starts a comment
    // anywhere on a line, as for the checks here (CGAL would read 'f 1 2#x 3' as 1 2 3).
    statements([&](size_t first, size_t end) {
      if (keyword(first, end, 'l')) text[first] = '#';
      // Searched within the line only (found by an audit: text.find ran to the file's end on
      // every line of a file without '#', 22 s for 12 MB).
      const size_t hash = static_cast<size_t>(std::find(text.begin() + first, text.begin() + end, '#') - text.begin());
      if (hash < end && hash != first)
        for (size_t i = hash; i < end; ++i)
          if (text[i] != '\r') text[i] = ' ';
    });
    const std::string problem = checkObjFaces(text);
    if (!problem.empty()) fail(path, problem);
    // Corners checked, each is cut to its vertex index: CGAL skips what follows the integer
    // with ignore(256, ' '), so a longer '/t/n' part was read on as further corners.
    statements([&](size_t first, size_t end) {
      if (!keyword(first, end, 'f')) return;
      bool in_suffix = false;
      for (size_t i = first + 1; i < end; ++i) {
        if (text[i] == ' ' || text[i] == '\r') in_suffix = false;
        else if (text[i] == '/') in_suffix = true;
        if (in_suffix) text[i] = ' ';
      }
    });
    cgal_text.str(std::move(text));
  }
  bool from_memory = format == Format::kObj || (format == Format::kStl && !read_here);
  if (format == Format::kOff) {
    const std::string problem = checkOffBody(in, off_header);
    if (!problem.empty()) fail(path, problem);
    // The numbers after a vertex's coordinates (checked above) are not read: CGAL 5.5 reads
    // texture coordinates from uninitialised indices when a file has no colours (found by
    // review), so it is given the keyword without ST, C and N ('4' stays: it divides).
    if (off_header.textures || off_header.colors || off_header.normals) {
      in.clear();
      in.seekg(0);
      std::string text(std::istreambuf_iterator<char>(in), {});
      if (in.bad() || text.size() < off_header.keyword_offset + off_header.keyword.size()) fail(path, "read error");
      const std::string plain = off_header.homogeneous ? "4OFF" : "OFF";
      text.replace(off_header.keyword_offset, off_header.keyword.size(),
                   plain + std::string(off_header.keyword.size() - plain.size(), ' '));
      cgal_text.str(std::move(text));
      from_memory = true;
    }
  }
  StringInput ply_buffer(std::move(ply_text));  // read in place: it may be twice the file
  std::istream ply_source(&ply_buffer);
  std::istream& source = ply_reencoded ? ply_source : from_memory ? static_cast<std::istream&>(cgal_text) : in;
  in.clear();
  in.seekg(0);
  if (!in) fail(path, "cannot rewind the file");

  bool ok = read_here;
  if (!read_here) try {
    const auto quiet = CGAL::parameters::verbose(false);
    switch (format) {
      case Format::kOff: ok = CGAL::IO::read_OFF(source, points, polygons, quiet); break;
      case Format::kObj: ok = CGAL::IO::read_OBJ(source, points, polygons, quiet); break;
      case Format::kPly: ok = CGAL::IO::read_PLY(source, points, polygons, quiet); break;
      case Format::kStl: ok = CGAL::IO::read_STL(source, points, polygons, quiet); break;
    }
  } catch (const TooManyCorners& e) {
    fail(path, "a face declares " + std::to_string(e.count) + " corners (at most " +
                   std::to_string(kMaxPolygonCorners) + " are read)");
  } catch (const std::bad_alloc&) {
    fail(path, "out of memory while reading");
  } catch (const std::exception& e) {
    fail(path, std::string("CGAL's reader failed: ") + e.what());
  }
  if (!ok) {
    fail(path, cgalRejected(format));
  }

  Mesh mesh;
  mesh.name = path;
  if (points.size() >= kInvalidIndex) fail(path, "too many vertices (" + std::to_string(points.size()) + ")");
  mesh.positions.reserve(points.size());
  for (const CgalPoint& p : points) mesh.positions.emplace_back(p.x(), p.y(), p.z());

  std::size_t triangle_count = 0;
  for (std::size_t f = 0; f < polygons.size(); ++f) {
    const Corners& corners = polygons[f];
    if (corners.size() < 3)
      fail(path, "face " + std::to_string(f) + " has " + plural(corners.size(), "corner") +
                     " (at least 3 needed)");
    for (std::size_t v : corners) {
      // CGAL's PLY reader makes a negative int index (a char or short one too, re-encoded as
      // int) a size_t (found by review: -1 was reported as 18446744073709551615).
      if (static_cast<std::int64_t>(v) < 0)
        fail(path, "face " + std::to_string(f) + " uses the negative vertex index " +
                       std::to_string(static_cast<std::int64_t>(v)));
      if (v >= points.size())
        fail(path, "face " + std::to_string(f) + " uses vertex " + std::to_string(v) +
                       " but the file has " + plural(points.size(), "vertex"));
    }
    triangle_count += corners.size() - 2;
  }
  if (triangle_count == 0) fail(path, "the file has no faces");
  mesh.triangles.reserve(triangle_count);
  // triangle_count + 2 * faces corners in all.
  std::uint64_t ear_work_left = kEarWorkBase + kEarWorkPerCorner * (triangle_count + 2 * polygons.size());
  std::vector<VertexIndex> ring;
  for (const Corners& corners : polygons) {
    ring.assign(corners.begin(), corners.end());
    triangulatePolygon(mesh.positions, ring, mesh.triangles, ear_work_left);
  }
  const std::string problem = checkMesh(mesh);
  if (!problem.empty()) throw MeshError(problem);
  return mesh;
}

}  // namespace

// A read error inside the readers' own loops (a device failing) names the file like every
// other error, as in readPoints (where an audit found the C++ library's own message escaping,
// on /proc/self/mem).
Mesh readMesh(const std::string& path) {
  errno = 0;
  try {
    return readMeshFrom(path);
  } catch (const std::ios_base::failure&) {
    fail(path, readError());
  }
}

void writeOff(const Mesh& mesh, const std::string& path) {
  std::ofstream out(path, std::ios::out | std::ios::trunc);
  if (!out.is_open()) fail(path, std::string("cannot write the file (") + std::strerror(errno) + ")");
  out.imbue(std::locale::classic());
  out.precision(std::numeric_limits<double>::max_digits10);
  out << "OFF\n" << mesh.positions.size() << ' ' << mesh.triangles.size() << " 0\n";
  for (const Vec3& p : mesh.positions) out << p.x() << ' ' << p.y() << ' ' << p.z() << '\n';
  for (const Triangle& t : mesh.triangles) out << "3 " << t[0] << ' ' << t[1] << ' ' << t[2] << '\n';
  out.close();
  if (out.fail()) fail(path, "write error (disk full?)");
}

std::vector<Vec3> readPoints(const std::string& path) {
  std::ifstream file;
  const bool from_stdin = path == "-";
  const std::string name = from_stdin ? std::string("<stdin>") : path;
  if (!from_stdin) {
    namespace fs = std::filesystem;
    std::error_code ec;
    const fs::file_status status = fs::status(path, ec);
    if (status.type() == fs::file_type::not_found) fail(path, "no such file");
    if (status.type() == fs::file_type::directory) fail(path, "is a directory, not a file");
    errno = 0;
    file.open(path);
    if (!file.is_open())
      fail(path, std::string("cannot open the file (") +
                     (errno != 0 ? std::strerror(errno) : "unknown reason") + ")");
  }
  std::istream& in = from_stdin ? std::cin : file;

  // A UTF-8 byte order mark (Windows editors write one) is dropped; a first line that starts
  // with its first byte only is garbage either way.
  if (in.peek() == 0xEF) {
    char mark[3] = {};
    in.read(mark, 3);
    if (in.gcount() != 3 || kUtf8Bom.compare(0, 3, mark, 3) != 0)
      throw MeshError(name + ":1: not a points file (starts with the byte 0xEF)");
  }
  std::vector<Vec3> points;
  std::string line;
  std::uint64_t line_number = 0;
  // Lines are read with a cap: a file without line breaks (/dev/zero) would grow one without
  // end (found by review).
  constexpr std::size_t kMaxLine = std::size_t(1) << 20;
  // A read error: a file's buffer throws it (a failing device, /proc/self/mem); standard input,
  // read through C's stdin, ends as if at the end, with its error flag set (a directory, a
  // closed descriptor). Either is reported, naming the input (found by an audit: standard
  // input's was taken for its end, zero points).
  auto nextLine = [&] {
    try {
      errno = 0;
      return nextDataLine(in, line, line_number, kMaxLine);
    } catch (const LineTooLong&) {
      throw MeshError(name + ":" + std::to_string(line_number + 1) + ": line longer than " +
                      std::to_string(kMaxLine) + " bytes (not a points file?)");
    } catch (const std::ios_base::failure&) {
      throw MeshError(name + ": " + readError());
    }
  };
  while (nextLine()) {
    const auto words = splitWords(line);
    const std::string at = name + ":" + std::to_string(line_number) + ": ";
    if (words.size() != 3) {
      // A CR inside the line (not its CRLF end): lines that end in CR alone, which are not
      // taken for line ends here (found by review: the message counted the fields of several).
      const std::size_t cr = line.find('\r');
      if (cr != std::string::npos && line.find_first_not_of("\r \t", cr) != std::string::npos)
        throw MeshError(at + "its lines end in CR alone (classic Mac OS): convert them to LF or CRLF");
      throw MeshError(at + "expected 3 numbers 'x y z', found " + plural(words.size(), "field"));
    }
    Vec3 p;
    for (int k = 0; k < 3; ++k) {
      switch (parseDouble(words[k], p[k])) {
        case NumberStatus::kOk: break;
        case NumberStatus::kNonFinite: throw MeshError(at + shown(words[k]) + " is not finite");
        case NumberStatus::kNotANumber: throw MeshError(at + shown(words[k]) + " is not a number");
      }
      if (std::abs(p[k]) > kMaxCoordinate)
        throw MeshError(at + shown(words[k]) + " is beyond 1e150 in magnitude (distances would overflow)");
    }
    points.push_back(p);
  }
  if (in.bad() || (from_stdin && std::ferror(stdin))) throw MeshError(name + ": " + readError());
  return points;
}

std::string escapedText(std::string_view text, bool escape_non_ascii) {
  std::string out;
  out.reserve(text.size());
  for (const char c : text) {
    const auto byte = static_cast<unsigned char>(c);
    if (byte >= 0x20 && byte != 0x7f && (byte < 0x80 || !escape_non_ascii)) {
      out += c;
      continue;
    }
    switch (byte) {
      case '\n': out += "\\n"; break;
      case '\r': out += "\\r"; break;
      case '\t': out += "\\t"; break;
      default: {
        char escaped[8];
        std::snprintf(escaped, sizeof escaped, "\\x%02x", byte);
        out += escaped;
      }
    }
  }
  return out;
}

}  // namespace meshsweeper
