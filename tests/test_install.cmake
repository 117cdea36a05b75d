# Install check, run by CTest as
#   cmake -DBUILD_DIR=... -DSOURCE_DIR=... -DWORK_DIR=... -DGENERATOR=... -DCXX_COMPILER=...
#         -DBUILD_TYPE=... -P test_install.cmake
# Installs the build tree into WORK_DIR/prefix, then configures and builds examples/ as an
# outside project that finds the library with find_package(meshsweeper CONFIG REQUIRED), and
# runs the example on a two-triangle mesh. Then configures the same project with
# add_subdirectory of the source tree.
cmake_minimum_required(VERSION 3.25)
foreach(var BUILD_DIR SOURCE_DIR WORK_DIR GENERATOR CXX_COMPILER)
  if(NOT DEFINED ${var})
    message(FATAL_ERROR "test_install.cmake: -D${var}=... is required")
  endif()
endforeach()

function(run what)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "install check: ${what} failed (${rc})\n${out}\n${err}")
  endif()
  set(run_output "${out}" PARENT_SCOPE)
endfunction()

set(prefix "${WORK_DIR}/prefix")
set(consumer "${WORK_DIR}/consumer")
file(REMOVE_RECURSE "${WORK_DIR}")
file(MAKE_DIRECTORY "${WORK_DIR}")

run("cmake --install" "${CMAKE_COMMAND}" --install "${BUILD_DIR}" --prefix "${prefix}")
if(NOT EXISTS "${prefix}/include/meshsweeper/core/sweep_query.h")
  message(FATAL_ERROR "install check: headers missing under ${prefix}/include/meshsweeper")
endif()

run("configuring the consumer" "${CMAKE_COMMAND}" -S "${SOURCE_DIR}/examples" -B "${consumer}"
    -G "${GENERATOR}" "-DCMAKE_CXX_COMPILER=${CXX_COMPILER}" "-DCMAKE_BUILD_TYPE=${BUILD_TYPE}"
    "-DCMAKE_PREFIX_PATH=${prefix}")
file(STRINGS "${consumer}/CMakeCache.txt" found_dir REGEX "^meshsweeper_DIR:")
string(FIND "${found_dir}" "${prefix}/" at)
if(at EQUAL -1)
  message(FATAL_ERROR "install check: find_package found '${found_dir}', not the test prefix")
endif()

run("building the consumer" "${CMAKE_COMMAND}" --build "${consumer}")

file(WRITE "${WORK_DIR}/quad.off" "OFF\n4 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n")
run("running the consumer" "${consumer}/closest_example" "${WORK_DIR}/quad.off" 0.25 0.75 -2)
string(FIND "${run_output}" "distance 2, triangle 1, point (0.25, 0.75, 0)" at)
if(at EQUAL -1)
  message(FATAL_ERROR "install check: unexpected output from the consumer:\n${run_output}")
endif()

# Programs that hand Eigen objects to the library (a rigid pose) must be compiled like it (an
# AVX-512 build aligns them to 64 bytes): a consumer built without the library's -march=native
# crashed in RigidBody::setPose.
run("running the rigid-body consumer" "${consumer}/rigid_body_example" "${WORK_DIR}/quad.off" 20)
string(FIND "${run_output}" "20 steps" at)
if(at EQUAL -1)
  message(FATAL_ERROR "install check: unexpected output from the rigid-body consumer:\n${run_output}")
endif()

# The same project with add_subdirectory of the source tree: configured and generated only
# (building would compile the library a second time), which checks that the tree works as a
# subproject and provides meshsweeper::meshsweeper.
run("configuring the add_subdirectory consumer" "${CMAKE_COMMAND}" -S "${SOURCE_DIR}/examples"
    -B "${WORK_DIR}/subdirectory" -G "${GENERATOR}" "-DCMAKE_CXX_COMPILER=${CXX_COMPILER}"
    "-DCMAKE_BUILD_TYPE=${BUILD_TYPE}" "-DMESHSWEEPER_SOURCE_DIR=${SOURCE_DIR}")
message("install check: installed, found with find_package, built and ran the consumer; "
        "configured it with add_subdirectory")
