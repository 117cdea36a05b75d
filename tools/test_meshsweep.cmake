# Tests of the meshsweep command line, run by CTest as
#   cmake -DMESHSWEEP=... -DEXAMPLE=... -DWORK_DIR=... [-DSERVICE_EXAMPLE=...] [-DDATA_DIR=...]
#         -P test_meshsweep.cmake
# Each case runs the tool once and checks its exit status, and substrings of its standard
# output and error. Expected rows come from a hand-drawn mesh with exact answers:
#
#   v3 (0,1) +-------+ v2 (1,1)     one quad face "4 0 1 2 3", fan-triangulated into
#            |     / |              triangle 0 = (v0, v1, v2)   below the diagonal
#            |  1 /  |              triangle 1 = (v0, v2, v3)   above it
#            |   / 0 |
#            |  /    |              query points:
#   v0 (0,0) +-------+ v1 (1,0)       0: (0.75, 0.25,  1)  above triangle 0, distance 1
#                                     1: (0.25, 0.75, -2)  below triangle 1, distance 2
#                                     2: (3, -4, 0)        nearest vertex v1, distance sqrt(20)
cmake_minimum_required(VERSION 3.25)
foreach(var MESHSWEEP EXAMPLE WORK_DIR)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "test_meshsweep.cmake: -D${var}=... is required")
  endif()
endforeach()

foreach(var MESHSWEEP EXAMPLE WORK_DIR)
  get_filename_component(${var} "${${var}}" ABSOLUTE)
endforeach()
if(SERVICE_EXAMPLE)
  get_filename_component(SERVICE_EXAMPLE "${SERVICE_EXAMPLE}" ABSOLUTE)
endif()

file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")
file(WRITE "${WORK_DIR}/quad.off" "OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")
file(WRITE "${WORK_DIR}/points.txt"
  "# three query points\n0.75 0.25 1\n\n0.25 0.75 -2\n3 -4 0   # far corner\n")
file(WRITE "${WORK_DIR}/short_line.txt" "0 0 0\n1 2\n")
file(WRITE "${WORK_DIR}/nan_point.txt" "0 0 nan\n")
file(WRITE "${WORK_DIR}/garbage.off" "this is not a mesh\n")

set(passed 0)
set(failed 0)
set(failures "")

# check(NAME RC <exit status> ARGS <arguments...> [INPUT file] [OUT substrings...]
#       [ERR substrings...] [NOT_OUT substrings...] [NOT_ERR substrings...] [COMMAND program])
function(check name)
  cmake_parse_arguments(C "" "RC;INPUT;COMMAND" "ARGS;OUT;ERR;NOT_OUT;NOT_ERR" ${ARGN})
  if(NOT C_COMMAND)
    set(C_COMMAND "${MESHSWEEP}")
  endif()
  set(input_args "")
  if(C_INPUT)
    set(input_args INPUT_FILE "${C_INPUT}")
  endif()
  execute_process(COMMAND "${C_COMMAND}" ${C_ARGS}
    WORKING_DIRECTORY "${WORK_DIR}" ${input_args}
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  set(problems "")
  if(NOT "${rc}" STREQUAL "${C_RC}")
    list(APPEND problems "exit status '${rc}', expected ${C_RC}")
  endif()
  foreach(text IN LISTS C_OUT)
    string(FIND "${out}" "${text}" at)
    if(at EQUAL -1)
      list(APPEND problems "stdout lacks '${text}'")
    endif()
  endforeach()
  foreach(text IN LISTS C_NOT_OUT)
    string(FIND "${out}" "${text}" at)
    if(NOT at EQUAL -1)
      list(APPEND problems "stdout has '${text}'")
    endif()
  endforeach()
  foreach(text IN LISTS C_ERR)
    string(FIND "${err}" "${text}" at)
    if(at EQUAL -1)
      list(APPEND problems "stderr lacks '${text}'")
    endif()
  endforeach()
  foreach(text IN LISTS C_NOT_ERR)
    string(FIND "${err}" "${text}" at)
    if(NOT at EQUAL -1)
      list(APPEND problems "stderr has '${text}'")
    endif()
  endforeach()
  if(problems)
    string(REPLACE ";" "\n    " problems "${problems}")
    message("FAIL ${name}: ${C_ARGS}\n    ${problems}\n  stdout: ${out}\n  stderr: ${err}")
    math(EXPR failed_now "${failed} + 1")
    set(failed ${failed_now} PARENT_SCOPE)
  else()
    math(EXPR passed_now "${passed} + 1")
    set(passed ${passed_now} PARENT_SCOPE)
  endif()
endfunction()

# same_files(PLAIN COHERENT): the two output files of WORK_DIR are byte for byte equal.
function(same_files plain coherent)
  file(READ "${WORK_DIR}/${plain}" plain_text)
  file(READ "${WORK_DIR}/${coherent}" coherent_text)
  if(plain_text STREQUAL coherent_text)
    math(EXPR passed_now "${passed} + 1")
    set(passed ${passed_now} PARENT_SCOPE)
  else()
    message("FAIL ${coherent} differs from ${plain}")
    math(EXPR failed_now "${failed} + 1")
    set(failed ${failed_now} PARENT_SCOPE)
  endif()
endfunction()

# expect(NAME CONDITION WHAT): CONDITION is an if() condition, evaluated here.
function(expect name condition what)
  cmake_language(EVAL CODE "if(${condition})\n set(ok TRUE)\nelse()\n set(ok FALSE)\nendif()")
  if(ok)
    math(EXPR passed "${passed} + 1")
  else()
    message("FAIL ${name}: ${what}")
    math(EXPR failed "${failed} + 1")
  endif()
  set(passed ${passed} PARENT_SCOPE)
  set(failed ${failed} PARENT_SCOPE)
endfunction()

set(header "point,rank,distance,lower,upper,triangle,x,y,z,b0,b1,b2\n")
set(row2 "\n2,0,4.4721359549995796,4.4721359549995796,4.4721359549995796,0,1,0,0,0,1,0\n")

# Exact closest points; the fan triangulation decides the triangle indices.
check(closest RC 0 ARGS closest quad.off points.txt
  OUT "${header}0,0,1,1,1,0,0.75" "\n1,0,2,2,2,1,0.25" "${row2}"
  ERR "\"mesh\": \"quad.off\"" "\"vertices\": 4" "\"triangles\": 2" "\"points\": 3"
      "\"rows\": 3" "\"build_seconds\": " "\"query_seconds\": " "\"mode\": \"closest\"")
check(closest_stdin RC 0 ARGS closest quad.off - INPUT "${WORK_DIR}/points.txt"
  OUT "${row2}" ERR "\"rows\": 3")
check(closest_out_file RC 0 ARGS closest quad.off points.txt --out closest.csv ERR "\"rows\": 3"
  NOT_OUT "point,rank")
set(written "")
if(EXISTS "${WORK_DIR}/closest.csv")
  file(READ "${WORK_DIR}/closest.csv" written)
endif()
string(FIND "${written}" "${header}0,0,1,1,1,0," at)
if(at EQUAL 0)
  math(EXPR passed "${passed} + 1")
else()
  message("FAIL closest_out_file: closest.csv holds: ${written}")
  math(EXPR failed "${failed} + 1")
endif()

# Anytime: tolerance 0 is exact; a large tolerance still answers every point.
check(anytime_exact RC 0 ARGS closest quad.off points.txt --tolerance 0
  OUT "\n0,0,1,1,1,0," "\n1,0,2,2,2,1," "${row2}" ERR "\"mode\": \"anytime\"")
check(anytime_loose RC 0 ARGS closest quad.off points.txt --tolerance=10
  OUT "\n0,0," "\n1,0," "\n2,0," ERR "\"rows\": 3")

# k closest: ranks by increasing distance; asking for more than the mesh has gives all.
check(k_closest RC 0 ARGS closest quad.off points.txt --k 2
  OUT "\n0,0,1,1,1,0," "\n0,1,1.06066017" "\n1,0,2,2,2,1," "\n1,1,2.03100960"
      "\n2,0,4.4721359549995796," "\n2,1,5,5,5,1,0,0,0,1,0,0\n"
  ERR "\"rows\": 6" "\"mode\": \"k\"")
check(k_more_than_triangles RC 0 ARGS closest quad.off points.txt --k 1000 ERR "\"rows\": 6")

# Within D: one row per triangle within D; a point with none prints no row.
check(within RC 0 ARGS closest quad.off points.txt --within 1.5
  OUT "\n0,0,1,1,1,0," "\n0,1,1.06066017" NOT_OUT "\n1," "\n2,"
  ERR "\"rows\": 2" "\"mode\": \"within\"")
check(within_none RC 0 ARGS closest quad.off points.txt --within 0 OUT "${header}"
  NOT_OUT "\n0," ERR "\"rows\": 0")

# Signed: a closed octahedron (|x| + |y| + |z| = 1, faces outward; inward, the same solid):
# (0.1, 0.1, 0.1) is inside, 0.7 / sqrt(3) from face 0; (1, 1, 1) outside, 2 / sqrt(3) from it;
# the vertex (1, 0, 0) on the surface (outside, signed distance 0). Every row of a point has the
# point's sign. The quad is open: refused with the reason, exit status 1.
set(octahedron_faces "3 0 2 4\n3 1 4 2\n3 0 4 3\n3 1 3 4\n3 0 5 2\n3 1 2 5\n3 0 3 5\n3 1 5 3\n")
file(WRITE "${WORK_DIR}/octahedron.off"
  "OFF\n6 8 0\n1 0 0\n-1 0 0\n0 1 0\n0 -1 0\n0 0 1\n0 0 -1\n${octahedron_faces}")
string(REGEX REPLACE "3 ([0-9]) ([0-9]) ([0-9])" "3 \\1 \\3 \\2" inward_faces "${octahedron_faces}")
file(WRITE "${WORK_DIR}/octahedron_inward.off"
  "OFF\n6 8 0\n1 0 0\n-1 0 0\n0 1 0\n0 -1 0\n0 0 1\n0 0 -1\n${inward_faces}")
file(WRITE "${WORK_DIR}/sides.txt" "0.1 0.1 0.1\n1 1 1\n1 0 0\n")
set(signed_header "point,rank,distance,lower,upper,triangle,x,y,z,b0,b1,b2,sign,signed_distance\n")
foreach(mesh octahedron octahedron_inward)
  check(signed_${mesh} RC 0 ARGS closest ${mesh}.off sides.txt --signed
    OUT "${signed_header}0,0,0.40414518843273806," ",-1,-0.40414518843273806\n"
        "\n1,0,1.1547005383792517," ",1,1.1547005383792517\n" "\n2,0,0,0,0," ",1,0\n"
    ERR "\"rows\": 3" "\"inside\": 1")
endforeach()
check(signed_path RC 0 ARGS closest octahedron.off sides.txt --signed --path
  OUT ",-1,-0.40414518843273806\n" ",1,1.1547005383792517\n" ERR "\"inside\": 1" "\"certified\": ")
check(signed_k RC 0 ARGS closest octahedron.off sides.txt --signed --k 2
  OUT "\n0,1,0.51961524227066314," ",-1,-0.51961524227066314\n" "\n1,1,1.2247448713915889," ",1,1.2247448713915889\n"
  ERR "\"rows\": 6")
check(signed_within RC 0 ARGS closest octahedron.off sides.txt --signed --within 0.5
  OUT ",-1,-0.40414518843273806\n" "\n2,3,0,0,0,6," NOT_OUT "\n1,"
  ERR "\"rows\": 5" "\"inside\": 1")
check(unsigned_columns RC 0 ARGS closest octahedron.off sides.txt OUT "${header}" NOT_OUT "sign" NOT_ERR "inside")
check(signed_open RC 1 ARGS closest quad.off points.txt --signed
  ERR "meshsweep: quad.off: distances cannot be signed: the mesh is not closed (edge (0, 1) has 1 face (boundary))")
check(info_closed RC 0 ARGS info octahedron.off --queries 5 OUT "\"closed\": true}" NOT_OUT "open_reason")
check(info_open RC 0 ARGS info quad.off --queries 5
  OUT "\"closed\": false, \"open_reason\": \"edge (0, 1) has 1 face (boundary)\"}")
check(signed_tolerance RC 2 ARGS closest octahedron.off sides.txt --signed --tolerance 0.1
  ERR "--signed needs exact closest points")

# Help.
check(help RC 0 ARGS help OUT "closest" "sample")
check(help_flag RC 0 ARGS --help OUT "Usage: meshsweep COMMAND")
check(help_closest RC 0 ARGS help closest OUT "point,rank,distance,lower,upper,triangle")
# Found by review: the help said polygons are fan-triangulated; non-convex ones are cut into ears.
check(help_closest_polygons RC 0 ARGS help closest OUT "cut into ears" NOT_OUT "fan-triangulated")
check(closest_help_flag RC 0 ARGS closest --help OUT "--tolerance")
check(no_arguments RC 2 ERR "Usage: meshsweep COMMAND")

# Command-line errors: exit status 2, one "meshsweep: " line, never a crash.
check(unknown_command RC 2 ARGS frobnicate ERR "meshsweep: unknown command 'frobnicate'")
check(help_unknown RC 2 ARGS help frobnicate ERR "meshsweep: help: unknown command")
check(missing_points RC 2 ARGS closest quad.off ERR "meshsweep: closest: missing argument POINTS")
check(missing_mesh RC 2 ARGS closest ERR "meshsweep: closest: missing argument MESH")
check(extra_argument RC 2 ARGS closest quad.off points.txt extra ERR "unexpected argument 'extra'")
# Found by an audit: a mesh named '-' said "-: no such file"; standard input is for points only.
check(mesh_stdin_closest RC 2 ARGS closest - points.txt
  ERR "meshsweep: closest: a mesh is read from a file, not from standard input")
check(mesh_stdin_hausdorff RC 2 ARGS hausdorff quad.off - ERR "meshsweep: hausdorff: a mesh is read from a file")
check(mesh_stdin_info RC 2 ARGS info - ERR "meshsweep: info: a mesh is read from a file")
check(mesh_stdin_sample RC 2 ARGS sample - 5 ERR "meshsweep: sample: a mesh is read from a file")
check(mesh_stdin_check RC 2 ARGS check - ERR "meshsweep: check: a mesh is read from a file")
check(unknown_option RC 2 ARGS closest quad.off points.txt --fast
  ERR "meshsweep: closest: unknown option --fast")
check(missing_value RC 2 ARGS closest quad.off points.txt --tolerance ERR "needs a value")
check(negative_tolerance RC 2 ARGS closest quad.off points.txt --tolerance -1 ERR "negative")
check(nan_tolerance RC 2 ARGS closest quad.off points.txt --tolerance nan ERR "finite")
check(inf_within RC 2 ARGS closest quad.off points.txt --within inf ERR "finite")
check(negative_within RC 2 ARGS closest quad.off points.txt --within -0.5 ERR "negative")
check(garbage_tolerance RC 2 ARGS closest quad.off points.txt --tolerance 1e-3x ERR "finite")
# Decimal notation only (strtod read "0x10" as 16); past the largest double is not "not finite";
# below the smallest, the value rounds and the option's own range decides (from a review).
check(hex_tolerance RC 2 ARGS closest quad.off points.txt --tolerance 0x10
  ERR "--tolerance must be a finite decimal number (got '0x10')")
check(huge_tolerance RC 2 ARGS closest quad.off points.txt --tolerance 1e999
  ERR "--tolerance is beyond the largest double, 1.8e308 (got '1e999')")
check(tiny_relative RC 2 ARGS hausdorff quad.off quad.off --relative 1e-400 ERR "--relative must be > 0")
check(subnormal_relative RC 0 ARGS hausdorff quad.off quad.off --relative 1e-320 OUT "tolerance 4e-12")
check(zero_k RC 2 ARGS closest quad.off points.txt --k 0 ERR "--k must be an integer")
check(negative_k RC 2 ARGS closest quad.off points.txt --k -3 ERR "--k must be an integer")
check(fraction_k RC 2 ARGS closest quad.off points.txt --k 1.5 ERR "--k must be an integer")
check(huge_k RC 2 ARGS closest quad.off points.txt --k 99999999999999999999 ERR "--k must be")
check(k_and_within RC 2 ARGS closest quad.off points.txt --k 2 --within 1 ERR "cannot be combined")
# --within has no coherent form in the tool: --path with it is refused, not silently ignored.
check(within_path RC 2 ARGS closest quad.off points.txt --within 1 --path
  ERR "meshsweep: closest: --path cannot be combined with --within")
check(repeated_option RC 2 ARGS closest quad.off points.txt --k 2 --k 3 ERR "given twice")

# Input and output file errors: exit status 1.
check(no_mesh_file RC 1 ARGS closest absent.off points.txt ERR "meshsweep: " "absent.off")
check(garbage_mesh RC 1 ARGS closest garbage.off points.txt ERR "meshsweep: " "garbage.off")
check(no_points_file RC 1 ARGS closest quad.off absent.txt ERR "meshsweep: " "absent.txt")
check(short_point_line RC 1 ARGS closest quad.off short_line.txt ERR "meshsweep: " "short_line.txt")
check(nan_point RC 1 ARGS closest quad.off nan_point.txt ERR "meshsweep: " "nan_point.txt")
check(unwritable_out RC 1 ARGS closest quad.off points.txt --out no/such/dir/out.csv
  ERR "meshsweep: no/such/dir/out.csv")

# sample: reproducible, readable by closest.
check(sample RC 0 ARGS sample quad.off 5 --near 0.01 --seed 7 --out sample_a.txt)
check(sample_again RC 0 ARGS sample quad.off 5 --near=0.01 --seed=7 --out sample_b.txt)
set(sample_a "")
set(sample_b "")
if(EXISTS "${WORK_DIR}/sample_a.txt" AND EXISTS "${WORK_DIR}/sample_b.txt")
  file(READ "${WORK_DIR}/sample_a.txt" sample_a)
  file(READ "${WORK_DIR}/sample_b.txt" sample_b)
endif()
if(sample_a STREQUAL sample_b AND NOT sample_a STREQUAL "")
  math(EXPR passed "${passed} + 1")
else()
  message("FAIL sample_reproducible:\n${sample_a}\n---\n${sample_b}")
  math(EXPR failed "${failed} + 1")
endif()
check(sample_then_closest RC 0 ARGS closest quad.off sample_a.txt ERR "\"points\": 5" "\"rows\": 5")
check(sample_box RC 0 ARGS sample quad.off 3 OUT "# meshsweep sample quad.off 3 --box 0.1 --seed 1")
check(sample_zero RC 2 ARGS sample quad.off 0 ERR "sample: N must be an integer")
check(sample_two_modes RC 2 ARGS sample quad.off 3 --near 0.1 --box 0.1 ERR "cannot be combined")
check(sample_no_mesh RC 1 ARGS sample absent.off 3 ERR "meshsweep: " "absent.off")
check(sample_negative RC 2 ARGS sample quad.off -5
  ERR "meshsweep: sample: N must be an integer in [1, 100000000] (got '-5')")
# The whole uint64 range of seeds, as the message says.
check(sample_seed_max RC 0 ARGS sample quad.off 2 --seed 18446744073709551615
  OUT "--seed 18446744073709551615\n")
check(sample_seed_over RC 2 ARGS sample quad.off 2 --seed 18446744073709551616
  ERR "--seed must be an integer in [0, 18446744073709551615] (got 18446744073709551616)")
# A fraction whose points could leave the coordinate range (+-1e150) is refused: --box 1e308
# printed 'inf inf inf', --near 1e200 coordinates that closest refuses. quad.off's diagonal is
# sqrt(2) and its farthest coordinate 1, so F may be up to (1e150 - 1) / sqrt(2) = 7.0710678e149.
check(sample_box_huge RC 2 ARGS sample quad.off 3 --box 1e308
  ERR "meshsweep: sample: --box must be at most 7.07106e+149 for quad.off" "got 1e308"
  NOT_OUT "inf")
check(sample_near_huge RC 2 ARGS sample quad.off 3 --near 1e200
  ERR "meshsweep: sample: --near must be at most 7.07106e+149 for quad.off")
check(sample_box_over RC 2 ARGS sample quad.off 3 --box 7.07107e149 ERR "--box must be at most")
check(sample_box_limit RC 0 ARGS sample quad.off 50 --box 7.07106e149 --out sample_box_limit.txt)
check(sample_box_limit_closest RC 0 ARGS closest quad.off sample_box_limit.txt ERR "\"rows\": 50")
check(sample_near_limit RC 0 ARGS sample quad.off 50 --near 7.07106e149 --out sample_near_limit.txt)
check(sample_near_limit_closest RC 0 ARGS closest quad.off sample_near_limit.txt
  ERR "\"rows\": 50")

# Threads: the rows do not depend on them (one stream per thread, blocks of 64 points, written
# in point order; the chunks follow the rows per point). Points over the quad tie between its
# triangles along the diagonal and at the vertices; --within 1e9 gives two rows per point.
check(threads_sample RC 0 ARGS sample quad.off 3000 --near 0.3 --seed 7 --out threads_points.txt)
file(APPEND "${WORK_DIR}/threads_points.txt" "0.5 0.5 1\n1 1 0\n0 0 -0.5\n")
# The signed rows on the closed octahedron, from points on both sides.
check(threads_sample_signed RC 0 ARGS sample octahedron.off 3000 --near 0.3 --seed 8 --out threads_signed_points.txt)
foreach(mode_args "closest" "closest;--k;2" "closest;--within;1e9" "closest;--within;0.1"
                  "closest;--tolerance;0.05" "closest;--signed;--k;2")
  string(REPLACE ";" "_" mode_name "${mode_args}")
  set(mesh quad.off)
  set(mode_points threads_points.txt)
  if(mode_name MATCHES "signed")
    set(mesh octahedron.off)
    set(mode_points threads_signed_points.txt)
  endif()
  foreach(threads 1 2 0)
    check(threads_${mode_name}_${threads} RC 0
      ARGS ${mode_args} ${mesh} ${mode_points} --threads ${threads} --out threads_${mode_name}_${threads}.csv)
  endforeach()
  same_files(threads_${mode_name}_1.csv threads_${mode_name}_2.csv)
  same_files(threads_${mode_name}_1.csv threads_${mode_name}_0.csv)
endforeach()
# Rows in point order, ranks in order: row r of --k 2 is point r / 2, rank r % 2.
file(STRINGS "${WORK_DIR}/threads_closest_--k_2_2.csv" k_lines)
list(LENGTH k_lines k_count)
list(REMOVE_AT k_lines 0)  # the header
set(k_order_ok TRUE)
set(r 0)
foreach(line IN LISTS k_lines)
  math(EXPR point "${r} / 2")
  math(EXPR rank "${r} % 2")
  string(FIND "${line}" "${point},${rank}," at)
  if(NOT at EQUAL 0)
    set(k_order_ok FALSE)
    break()
  endif()
  math(EXPR r "${r} + 1")
endforeach()
expect(threads_order "k_order_ok AND k_count EQUAL 6007" "--k 2 rows out of order (${k_count} lines)")
check(threads_count RC 0 ARGS closest quad.off points.txt --threads 1 ERR "\"threads\": 1")
check(threads_path RC 2 ARGS closest quad.off points.txt --path --threads 2
  ERR "meshsweep: closest: --path answers its points in order with one stream: --threads must be 1 with it")
check(threads_path_one RC 0 ARGS closest quad.off points.txt --path --threads 1 ERR "\"threads\": 1")
check(threads_bad RC 2 ARGS closest quad.off points.txt --threads two ERR "--threads must be")

# The README's library example.
check(example RC 0 COMMAND "${EXAMPLE}" ARGS quad.off 0.75 0.25 1
  OUT "distance 1, triangle 0, point (0.75, 0.25, 0)")
check(example_bad_mesh RC 1 COMMAND "${EXAMPLE}" ARGS absent.off 0 0 0 ERR "closest_example: ")

# The README's distance-service example: STEPS must be a positive integer (atoi ran 0 steps).
if(SERVICE_EXAMPLE)
  check(service_example RC 0 COMMAND "${SERVICE_EXAMPLE}" ARGS quad.off 1 OUT "step  0: ")
  check(service_example_text RC 2 COMMAND "${SERVICE_EXAMPLE}" ARGS quad.off abc
    ERR "service_example: STEPS must be a positive integer (got 'abc')" NOT_OUT "step")
  check(service_example_negative RC 2 COMMAND "${SERVICE_EXAMPLE}" ARGS quad.off -3
    ERR "service_example: STEPS must be a positive integer (got '-3')" NOT_OUT "step")
endif()

# scene checks its output before running anything: a file as DIR, or a directory where the
# picture goes, fails at once (no scene's console output).
check(scene_out_not_directory RC 1 ARGS scene all --out quad.off
  ERR "meshsweep: quad.off: not a directory" NOT_OUT "scene " "hausdorff:")
file(MAKE_DIRECTORY "${WORK_DIR}/scene_blocked/particle.png")
check(scene_out_blocked RC 1 ARGS scene particle --out scene_blocked
  ERR "meshsweep: scene_blocked/particle.png: cannot open for writing" NOT_OUT "particle:")
# `scene all` goes on past a scene that fails (the hausdorff scene without its meshes), names it
# and exits 1; the particle and cloth scenes, which read no mesh, still write their pictures.
check(scene_all_goes_on RC 1 COMMAND env
  ARGS MESHSWEEPER_DATA=/nonexistent-meshsweeper-data "${MESHSWEEP}" scene all --out scene_all
  ERR "meshsweep: scene hausdorff: /nonexistent-meshsweeper-data/armadillo.off"
  OUT "scene particle: scene_all/particle.png" "scene cloth: scene_all/cloth.png" NOT_OUT "scene hausdorff:")

# A real mesh, when scripts/fetch_data.sh has extracted them.
if(DATA_DIR AND EXISTS "${DATA_DIR}/armadillo.off")
  check(real_sample RC 0 ARGS sample "${DATA_DIR}/armadillo.off" 200 --near 0.01 --seed 1
    --out real_points.txt)
  check(real_closest RC 0 ARGS closest "${DATA_DIR}/armadillo.off" real_points.txt
    --out real.csv ERR "\"points\": 200" "\"rows\": 200")
  check(real_k RC 0 ARGS closest "${DATA_DIR}/armadillo.off" real_points.txt --k 3
    --out real_k.csv ERR "\"rows\": 600")
  check(real_info RC 0 ARGS info "${DATA_DIR}/armadillo.off" --queries 50
    OUT "\"triangles\": 52000" "\"fixed_bytes_per_triangle\"" "\"stream_state_bytes\"")
  # --path answers with a coherent stream: the same CSV, byte for byte, for every mode.
  check(real_path RC 0 ARGS closest "${DATA_DIR}/armadillo.off" real_points.txt --path
    --out real_path.csv ERR "\"path\": true" "\"certified\": ")
  check(real_path_k RC 0 ARGS closest "${DATA_DIR}/armadillo.off" real_points.txt --path --k 3
    --out real_path_k.csv ERR "\"rows\": 600")
  same_files(real.csv real_path.csv)
  same_files(real_k.csv real_path_k.csv)
  # Many rows per point: within 1000 of the armadillo is every one of its 52,000 triangles.
  # After three such points a chunk holds 2^17 rows and stops; the next starts at the fourth.
  # The same rows as --k 52000 (ties by triangle). With 120 points that reach a part of the
  # mesh after them (about 1,000 rows each), another thread answers some of those while the
  # first is busy: their rows are dropped and answered again, and 1 and 2 threads give the
  # same file. With 40 far points (no row) first, the stop comes in the chunk's last block.
  file(STRINGS "${WORK_DIR}/real_points.txt" real_lines REGEX "^[^#]")
  list(SUBLIST real_lines 0 4 real_lines)
  list(JOIN real_lines "\n" near_four)
  file(WRITE "${WORK_DIR}/near_four.txt" "${near_four}\n")
  set(far_first "")
  foreach(f RANGE 39)
    string(APPEND far_first "1e7 ${f} 0\n")
  endforeach()
  file(WRITE "${WORK_DIR}/far_first.txt" "${far_first}${near_four}\n")
  check(real_within_all RC 0 ARGS closest "${DATA_DIR}/armadillo.off" near_four.txt --within 1000
    --threads 2 --out real_within_all.csv ERR "\"rows\": 208000")
  check(real_k_all RC 0 ARGS closest "${DATA_DIR}/armadillo.off" near_four.txt --k 52000
    --out real_k_all.csv ERR "\"rows\": 208000")
  same_files(real_within_all.csv real_k_all.csv)
  set(reach_after "")
  foreach(f RANGE 119)
    math(EXPR x "1050 + ${f}")
    string(APPEND reach_after "${x} ${f} 0\n")
  endforeach()
  file(WRITE "${WORK_DIR}/reach_after.txt" "${near_four}\n${reach_after}")
  foreach(threads 1 2)
    check(real_far_first_${threads} RC 0 ARGS closest "${DATA_DIR}/armadillo.off" far_first.txt --within 1000
      --threads ${threads} --out real_far_first_${threads}.csv ERR "\"rows\": 208000")
    check(real_reach_after_${threads} RC 0 ARGS closest "${DATA_DIR}/armadillo.off" reach_after.txt --within 1000
      --threads ${threads} --out real_reach_after_${threads}.csv)
  endforeach()
  same_files(real_far_first_1.csv real_far_first_2.csv)
  same_files(real_reach_after_1.csv real_reach_after_2.csv)
  file(READ "${WORK_DIR}/real_far_first_2.csv" far_rows LIMIT 200)
  expect(real_far_first_rows "far_rows MATCHES \"\\n40,0,\"" "far_first's rows start at point 40")
  file(REMOVE "${WORK_DIR}/real_within_all.csv" "${WORK_DIR}/real_k_all.csv" "${WORK_DIR}/real_far_first_1.csv"
    "${WORK_DIR}/real_far_first_2.csv" "${WORK_DIR}/real_reach_after_1.csv" "${WORK_DIR}/real_reach_after_2.csv")
  # The scene's certified bounds and percentages are rounded outward (rounded to nearest, the
  # lower percentage printed as 0.8451%, above the proven value).
  check(scene_hausdorff RC 0 ARGS scene hausdorff --out scene_hausdorff
    OUT "hausdorff: H(simplified, original) in [1.93359, 1.95391] (0.8450% .. 0.8540% ")
endif()

# Ties: points over the vertices and edge midpoints of a grid are equidistant from several
# triangles; a coherent (--path) run must report the same triangles as a plain one.
file(WRITE "${WORK_DIR}/grid.off" "OFF\n9 4 0\n0 0 0\n1 0 0\n2 0 0\n0 1 0\n1 1 0\n2 1 0\n0 2 0\n1 2 0\n2 2 0\n"
  "4 0 1 4 3\n4 1 2 5 4\n4 3 4 7 6\n4 4 5 8 7\n")
set(tie_points "")
foreach(h 0.5 0.25 0.75 0.1 0.3)
  foreach(xy "1 1" "0.5 1" "1 0.5" "1.5 1" "1 1.5" "0 0" "2 2" "1 0" "0.5 0.5")
    string(APPEND tie_points "${xy} ${h}\n")
  endforeach()
endforeach()
file(WRITE "${WORK_DIR}/tie_points.txt" "${tie_points}")
check(ties_plain RC 0 ARGS closest grid.off tie_points.txt --out ties_plain.csv ERR "\"rows\": 45")
check(ties_path RC 0 ARGS closest grid.off tie_points.txt --path --out ties_path.csv ERR "\"rows\": 45")
check(ties_path_exact RC 0 ARGS closest grid.off tie_points.txt --path --tolerance 0 --out ties_front.csv
  ERR "\"rows\": 45")
same_files(ties_plain.csv ties_path.csv)
same_files(ties_plain.csv ties_front.csv)

# The summary's certified interval is printed rounded outward: h(quad -> point (3, 1, 2)) is
# sqrt(14) = 3.74165738..., so its upper bound prints as 3.741658, not 3.741657.
# check: a band OpenVDB cannot hold is refused before anything is built, naming the mesh (found
# by review: a needle at a voxel of 1e-6 ran out of memory and aborted; a voxel of 1e160 printed
# a perfect score); with no point a voxel out, the sign beyond one voxel is n/a, not 100%.
file(WRITE "${WORK_DIR}/needle.off" "OFF\n3 1 0\n0 0 0\n1 0 0\n1 1e-12 0\n3 0 1 2\n")
file(WRITE "${WORK_DIR}/tetra.off" "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n")
check(check_needle_fine RC 1 ARGS check needle.off --voxel 1e-6 ERR "needle.off" "leaf nodes" "choose a larger voxel")
check(check_band_huge RC 1 ARGS check tetra.off --band 1000 ERR "tetra.off" "leaf nodes" "narrower band")
check(check_voxel_huge RC 1 ARGS check tetra.off --voxel 1e160 ERR "tetra.off" "beyond the coordinate range")
check(check_band_two RC 0 ARGS check tetra.off --band 2 --points 200
      OUT "sign agreement beyond one voxel: n/a" NOT_OUT "100.0000% (0 of 0)")
check(check_needle RC 0 ARGS check needle.off --voxel 1e-3 --points 200 OUT "max disagreement")

file(WRITE "${WORK_DIR}/point.off" "OFF\n3 1 0\n3 1 2\n3 1 2\n3 1 2\n3 0 1 2\n")
check(hausdorff_outward RC 0 ARGS hausdorff quad.off point.off
  OUT "Hausdorff distance in [3.741657, 3.741658]" "B -> A  max in [2.828427, 2.828428]"
      "(264.57513% .. 264.57514% of diagonal)")

# --json and --colors to one destination would lose the JSON (the PLY is written last).
check(hausdorff_same_file RC 2 ARGS hausdorff quad.off point.off --json same.out --colors same.out
  ERR "meshsweep: hausdorff: --json and --colors cannot write to the same file 'same.out'")
check(hausdorff_same_file_two_names RC 2 ARGS hausdorff quad.off point.off --json ./same.out
  --colors same.out ERR "cannot write to the same file")
check(hausdorff_same_stdout RC 2 ARGS hausdorff quad.off point.off --json - --colors -
  ERR "cannot write to the same standard output")
# A dangling link to the JSON file, and standard output under another name (found by review).
file(CREATE_LINK "linked.json" "${WORK_DIR}/link.json" SYMBOLIC)
check(hausdorff_same_file_dangling_link RC 2 ARGS hausdorff quad.off point.off --json linked.json
  --colors link.json ERR "cannot write to the same file")
check(hausdorff_same_stdout_two_names RC 2 ARGS hausdorff quad.off point.off --json - --colors /dev/stdout
  ERR "cannot write to the same standard output")
check(hausdorff_json_stdout_colors RC 0 ARGS hausdorff quad.off point.off --json - --colors colors.ply
  OUT "\"hausdorff\": {\"lower\": 3.74165" ERR "Hausdorff distance in [")
if(EXISTS "${WORK_DIR}/same.out")
  message("FAIL hausdorff_same_file: a refused command created same.out")
  math(EXPR failed "${failed} + 1")
else()
  math(EXPR passed "${passed} + 1")
endif()
set(colors "")
if(EXISTS "${WORK_DIR}/colors.ply")
  file(READ "${WORK_DIR}/colors.ply" colors LIMIT 4)
endif()
expect(hausdorff_json_stdout_colors "colors STREQUAL \"ply\n\"" "colors.ply starts with '${colors}'")

# Found by an audit: a vertex no triangle uses has no distance; --colors wrote it as 0 and
# blue (touching B). It is written with quality -1, grey. A tolerance below the rounding floor
# is raised, and the summary says so (the JSON has both); a tolerance that parses as 0 says so.
file(WRITE "${WORK_DIR}/unused.off" "OFF\n5 1 0\n0 0 0\n1 0 0\n0 1 0\n7 7 7\n8 8 8\n3 0 1 2\n")
check(hausdorff_unused_colors RC 0 ARGS hausdorff unused.off point.off --colors unused.ply
  OUT "Hausdorff distance in [")
set(unused_ply "")
if(EXISTS "${WORK_DIR}/unused.ply")
  file(READ "${WORK_DIR}/unused.ply" unused_ply)
endif()
string(FIND "${unused_ply}" "\n7 7 7 -1 128 128 128\n8 8 8 -1 128 128 128\n3 0 1 2\n" at)
expect(hausdorff_unused_colors "NOT at EQUAL -1" "unused vertices not grey with quality -1:\n${unused_ply}")
check(hausdorff_tolerance_raised RC 0 ARGS hausdorff quad.off point.off --tolerance 1e-20 --json -
  ERR "(raised from the 1e-20 asked for: the least tolerance at these coordinates)"
  OUT "\"requested_tolerance\": 9.9999999999999995e-21")
check(hausdorff_tolerance_kept RC 0 ARGS hausdorff quad.off point.off --tolerance 1e-6
  NOT_OUT "raised from")
# --max-seconds: two triangulations of one square (the costly case: cells grow as 1 /
# tolerance) at 1e-9 stop at the limit with their interval, exit 0; a limit of 0 is refused.
file(WRITE "${WORK_DIR}/square_a.off" "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n")
file(WRITE "${WORK_DIR}/square_b.off" "OFF\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 3\n3 1 2 3\n")
check(hausdorff_max_seconds RC 0 ARGS hausdorff square_a.off square_b.off --relative 1e-9 --max-seconds 0.2
  --json - OUT "\"timed_out\": true" "\"converged\": false"
  ERR "(tolerance not reached: stopped by --max-seconds)")
check(hausdorff_max_seconds_zero RC 2 ARGS hausdorff quad.off point.off --max-seconds 0
  ERR "--max-seconds must be > 0 (got 0)")
# --max-memory: the same pair stops before its tables pass 16 MiB, exit 0; the default limit is
# reported; a size that is not a whole number of bytes (with K, M, G or T) is refused.
check(hausdorff_max_memory RC 0 ARGS hausdorff square_a.off square_b.off --tolerance 1e-9 --max-memory 16M
  --threads 1 --json - OUT "\"memory_limited\": true" "\"converged\": false" "\"max_memory_bytes\": 16777216"
  ERR "(tolerance not reached: stopped by the memory limit, --max-memory)")
check(hausdorff_memory_default RC 0 ARGS hausdorff quad.off quad.off --json -
  OUT "\"memory_limited\": false" "\"max_memory_bytes\": " "\"table_bytes\": " NOT_OUT "\"max_memory_bytes\": 0,")
check(hausdorff_max_memory_lower RC 0 ARGS hausdorff quad.off quad.off --max-memory 3g --json -
  OUT "\"max_memory_bytes\": 3221225472")
foreach(bad 0 1.5G 2X -5 5000000000G 4194305T)
  check(hausdorff_max_memory_bad_${bad} RC 2 ARGS hausdorff quad.off quad.off --max-memory ${bad}
    ERR "--max-memory must be a whole number of bytes from 1 to 2^62, or one with K, M, G or T (powers of 1024) (got '${bad}')")
endforeach()
check(hausdorff_tolerance_rounds_to_zero RC 2 ARGS hausdorff quad.off point.off --tolerance 1e-400
  ERR "--tolerance must be > 0 (got 1e-400, which rounds to 0)")
check(hausdorff_relative_zero RC 2 ARGS hausdorff quad.off point.off --relative 0.0
  ERR "--relative must be > 0 (got 0.0)")

# --colors to standard output (found by review): the PLY alone on standard output, the summary
# on standard error, also through /dev/stdout into a file (which reopened with truncation lost
# the PLY); empty names are refused; the coordinates keep every digit (a mesh at 1e9 was
# written as floats with 9 digits, its vertices collapsed).
check(hausdorff_colors_stdout RC 0 ARGS hausdorff quad.off point.off --colors -
  OUT "ply\nformat ascii 1.0" "property double x" NOT_OUT "Hausdorff distance in" ERR "Hausdorff distance in")
execute_process(COMMAND "${MESHSWEEP}" hausdorff quad.off point.off --colors /dev/stdout
  WORKING_DIRECTORY "${WORK_DIR}" OUTPUT_FILE "${WORK_DIR}/devstdout.ply" ERROR_VARIABLE err RESULT_VARIABLE rc)
file(READ "${WORK_DIR}/devstdout.ply" devstdout)
string(FIND "${devstdout}" "end_header" header_at)
if(rc EQUAL 0 AND devstdout MATCHES "^ply\n" AND NOT header_at EQUAL -1 AND err MATCHES "Hausdorff distance in")
  math(EXPR passed "${passed} + 1")
else()
  message("FAIL hausdorff_colors_devstdout: rc ${rc}, file starts '${devstdout}'")
  math(EXPR failed "${failed} + 1")
endif()
execute_process(COMMAND "${MESHSWEEP}" hausdorff quad.off point.off --json /dev/stdout
  WORKING_DIRECTORY "${WORK_DIR}" OUTPUT_VARIABLE json ERROR_VARIABLE err RESULT_VARIABLE rc)
if(rc EQUAL 0 AND json MATCHES "^{" AND NOT json MATCHES "Hausdorff distance" AND err MATCHES "Hausdorff distance in")
  math(EXPR passed "${passed} + 1")
else()
  message("FAIL hausdorff_json_devstdout: rc ${rc}, standard output '${json}'")
  math(EXPR failed "${failed} + 1")
endif()
check(hausdorff_empty_json RC 2 ARGS hausdorff quad.off point.off --json ""
  ERR "option --json needs a value")
check(hausdorff_empty_colors RC 2 ARGS hausdorff quad.off point.off --colors ""
  ERR "option --colors needs a value")
file(WRITE "${WORK_DIR}/far.off" "OFF\n3 1 0\n1000000000.0 0 0\n1000000000.5 0 0\n1000000000.0 0.5 0\n3 0 1 2\n")
check(hausdorff_colors_digits RC 0 ARGS hausdorff far.off far.off --colors -
  OUT "1000000000.5 0 0 ")
# Percentages of a tolerance far past the diagonal in exponent form, not 300 digits; none for
# a mesh of one point.
check(hausdorff_huge_percent RC 0 ARGS hausdorff quad.off quad.off --tolerance 1e300
  OUT "of A's diagonal)" NOT_OUT "00000000000000000000")
file(WRITE "${WORK_DIR}/dot.off" "OFF\n3 1 0\n1 1 1\n1 1 1\n1 1 1\n3 0 1 2\n")
check(hausdorff_zero_diagonal_percent RC 0 ARGS hausdorff dot.off quad.off --tolerance 0.1
  OUT "(n/a% of A's diagonal)" NOT_OUT "(0.00000%")

# Output files are written beside the destination and renamed over it: a run that fails
# leaves an existing file as it was (dot.off has a zero diagonal); one that succeeds replaces
# it, keeping its permissions; a link is written through.
file(WRITE "${WORK_DIR}/kept.json" "keep\n")
file(CHMOD "${WORK_DIR}/kept.json" PERMISSIONS OWNER_READ OWNER_WRITE GROUP_READ)
check(output_kept_on_error RC 1 ARGS hausdorff dot.off quad.off --json kept.json
  ERR "dot.off: all vertices coincide")
file(READ "${WORK_DIR}/kept.json" kept)
expect(output_kept_on_error_content "kept STREQUAL \"keep\n\"" "kept.json holds '${kept}'")
check(output_replaced RC 0 ARGS hausdorff quad.off dot.off --json kept.json OUT "Hausdorff distance in")
file(READ "${WORK_DIR}/kept.json" kept)
execute_process(COMMAND stat -c %a kept.json WORKING_DIRECTORY "${WORK_DIR}" OUTPUT_VARIABLE mode
  OUTPUT_STRIP_TRAILING_WHITESPACE)
string(FIND "${kept}" "\"hausdorff\"" at)
expect(output_replaced_content "NOT at EQUAL -1 AND mode STREQUAL 640" "mode '${mode}', kept.json holds '${kept}'")
file(MAKE_DIRECTORY "${WORK_DIR}/linked")
file(CREATE_LINK "linked/target.csv" "${WORK_DIR}/through.csv" SYMBOLIC)
check(output_through_link RC 0 ARGS closest quad.off points.txt --out through.csv ERR "\"rows\": 3")
file(READ "${WORK_DIR}/linked/target.csv" through)
string(FIND "${through}" "point,rank,distance" at)
expect(output_through_link_target "IS_SYMLINK \"${WORK_DIR}/through.csv\" AND at EQUAL 0"
  "through.csv should stay a link to linked/target.csv, which holds '${through}'")

# A report that cannot be written (a full device) is an error, whatever the command.
if(EXISTS /dev/full)
  foreach(command "info;quad.off" "closest;quad.off;points.txt" "hausdorff;quad.off;quad.off")
    execute_process(COMMAND "${MESHSWEEP}" ${command} WORKING_DIRECTORY "${WORK_DIR}"
      OUTPUT_FILE /dev/full RESULT_VARIABLE rc ERROR_VARIABLE err)
    string(FIND "${err}" "standard output: write failed" at)
    if(rc EQUAL 1 AND NOT at EQUAL -1)
      math(EXPR passed "${passed} + 1")
    else()
      message("FAIL ${command} > /dev/full: exit status '${rc}', stderr: ${err}")
      math(EXPR failed "${failed} + 1")
    endif()
  endforeach()
endif()

# hausdorff writes both its files whole before it puts either in place: a --colors that
# cannot be written leaves --json as it was (found by an audit: the JSON was replaced), also
# under a name with no room for ".partial-XXXXXX" (255 bytes at most; it was written in place).
string(REPEAT "n" 245 long_name)
set(long_name "${long_name}.json")
foreach(json kept2.json "${long_name}")
  file(WRITE "${WORK_DIR}/${json}" "keep\n")
  if(EXISTS /dev/full)
    check(output_both_or_neither RC 1 ARGS hausdorff quad.off quad.off --json "${json}" --colors /dev/full
      ERR "meshsweep: /dev/full: write failed")
    file(READ "${WORK_DIR}/${json}" kept)
    expect(output_both_or_neither_content "kept STREQUAL \"keep\n\"" "${json} holds '${kept}'")
  endif()
  check(output_both_written RC 0 ARGS hausdorff quad.off quad.off --json "${json}" --colors colors.ply
    OUT "Hausdorff distance in")
  file(READ "${WORK_DIR}/${json}" kept)
  string(FIND "${kept}" "\"hausdorff\"" at)
  expect(output_both_written_content "NOT at EQUAL -1" "${json} holds '${kept}'")
endforeach()
# The same for a JSON written in place (a file with two names): its old content is kept whole
# (found by review: it was written, then not cut, before the PLY failed).
if(EXISTS /dev/full)
  string(REPEAT "p" 3000 old_json)
  file(WRITE "${WORK_DIR}/linked1.json" "${old_json}")
  file(CREATE_LINK "${WORK_DIR}/linked1.json" "${WORK_DIR}/linked2.json")
  check(output_in_place_kept RC 1 ARGS hausdorff quad.off quad.off --json linked1.json --colors /dev/full
    ERR "/dev/full: write failed")
  file(READ "${WORK_DIR}/linked2.json" kept)
  expect(output_in_place_kept_content "kept STREQUAL old_json" "linked2.json changed")
endif()
file(GLOB hidden "${WORK_DIR}/.meshsweep-partial-*")
expect(no_short_temporaries "NOT hidden" "left behind: ${hidden}")

# An option's value is not read as an option ("--out -h" writes the file "-h"); an empty value
# is refused, not taken for standard output.
check(help_word_as_value RC 0 ARGS closest quad.off points.txt --out -h ERR "\"rows\": 3" NOT_OUT "Usage:")
expect(help_word_as_value_file "EXISTS \"${WORK_DIR}/-h\"" "closest --out -h wrote no file '-h'")
check(empty_value RC 2 ARGS closest quad.off points.txt --out=
  ERR "meshsweep: closest: option --out needs a value, got an empty one")
check(help_anywhere RC 0 ARGS closest --bogus --help OUT "Usage: meshsweep closest")
check(help_help RC 0 ARGS help --help OUT "Usage: meshsweep help")
check(help_command_flag RC 0 ARGS help closest -h OUT "Usage: meshsweep closest")
# Another name of standard output (here a pipe) is written through the stream (found by an
# audit: it looked for a file beside /proc/self/fd/1).
check(out_names_stdout RC 0 ARGS closest quad.off points.txt --out /dev/stdout OUT "point,rank,distance")
check(hausdorff_relative_overflow RC 2 ARGS hausdorff quad.off quad.off --relative 1.7e308
  ERR "times A's diagonal is beyond the largest double")

# More threads than TBB allows (the cores) are capped quietly: no "TBB Warning" on stderr.
check(hausdorff_many_threads RC 0 ARGS hausdorff quad.off quad.off --threads 4096 --json -
  OUT "\"threads\": " NOT_ERR "TBB" "Warning")

# No run leaves a temporary output file behind.
file(GLOB_RECURSE partials "${WORK_DIR}/*.partial-*")
expect(no_temporaries "NOT partials" "left behind: ${partials}")

message("meshsweep_cli: ${passed} passed, ${failed} failed")
if(failed GREATER 0)
  message(FATAL_ERROR "meshsweep_cli: ${failed} case(s) failed")
endif()
