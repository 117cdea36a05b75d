# CTest entries for the command-line tool and the install; included from tests/CMakeLists.txt
# (CTest only sees tests registered after enable_testing()).
if(TARGET meshsweep)
  add_test(NAME meshsweep_cli COMMAND ${CMAKE_COMMAND}
    -DMESHSWEEP=$<TARGET_FILE:meshsweep> -DEXAMPLE=$<TARGET_FILE:closest_example>
    -DSERVICE_EXAMPLE=$<TARGET_FILE:service_example>
    -DWORK_DIR=${CMAKE_CURRENT_BINARY_DIR}/meshsweep_cli -DDATA_DIR=${MESHSWEEPER_DATA_DIR}
    -P ${PROJECT_SOURCE_DIR}/tools/test_meshsweep.cmake)
endif()

# Installs the build into a temporary prefix and builds examples/ against it with
# find_package(meshsweeper CONFIG REQUIRED).
add_test(NAME install_consumer COMMAND ${CMAKE_COMMAND}
  -DBUILD_DIR=${PROJECT_BINARY_DIR} -DSOURCE_DIR=${PROJECT_SOURCE_DIR}
  -DWORK_DIR=${CMAKE_CURRENT_BINARY_DIR}/install_consumer
  -DGENERATOR=${CMAKE_GENERATOR} -DCXX_COMPILER=${CMAKE_CXX_COMPILER}
  -DBUILD_TYPE=${CMAKE_BUILD_TYPE}
  -P ${PROJECT_SOURCE_DIR}/tests/test_install.cmake)
set_tests_properties(install_consumer PROPERTIES TIMEOUT 600)

# Scene smoke test: `meshsweep scene particle` (about 0.2 s) writes a non-empty file that starts
# with the PNG signature.
if(TARGET meshsweep)
  add_test(NAME meshsweep_scene_png COMMAND sh -c
    "rm -rf \"$1\" && \"$0\" scene particle --out \"$1\" && test -s \"$1/particle.png\" && head -c 8 \"$1/particle.png\" | od -An -tx1 | tr -d ' \\n' | grep -qx 89504e470d0a1a0a"
    $<TARGET_FILE:meshsweep> ${CMAKE_CURRENT_BINARY_DIR}/meshsweep_scene_png)
  set_tests_properties(meshsweep_scene_png PROPERTIES TIMEOUT 60)
endif()
