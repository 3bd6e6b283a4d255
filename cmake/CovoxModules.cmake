# The modules outside the library that the programs in tools/ and the tests share (cli/, sim/,
# eval/, runner/, benchmark/; docs/design.md, "Tools, modules and tests"), and the gtest
# executables. A module is a top-level folder of headers and sources, one static library
# covoxslam_<folder> that links the library and the modules named after DEPENDS; its headers are
# included by their folder ("sim/sim_world.h"), so the repository's root is on the include path.
# Static, so that the programs need no module library at run time and none is installed.
function(covox_add_module folder)
  cmake_parse_arguments(PARSE_ARGV 1 arg "" "" "DEPENDS")
  file(GLOB module_sources CONFIGURE_DEPENDS ${PROJECT_SOURCE_DIR}/${folder}/*.cpp)
  set(target covoxslam_${folder})
  add_library(${target} STATIC ${module_sources})
  target_include_directories(${target} PUBLIC ${PROJECT_SOURCE_DIR})
  target_link_libraries(${target} PUBLIC covoxslam ${arg_DEPENDS})
endfunction()

# One gtest executable from the *_test.cpp files of `folder` (and the SOURCES given), linked
# with LINK; each test is its own CTest entry, named Suite.Test whatever executable holds it.
function(covox_add_gtests target folder)
  cmake_parse_arguments(PARSE_ARGV 2 arg "" "" "SOURCES;LINK")
  file(GLOB test_sources CONFIGURE_DEPENDS ${PROJECT_SOURCE_DIR}/${folder}/*_test.cpp)
  add_executable(${target} ${test_sources} ${arg_SOURCES})
  target_link_libraries(${target} PRIVATE ${arg_LINK} GTest::gtest GTest::gtest_main)
  gtest_discover_tests(${target}
    DISCOVERY_TIMEOUT 120
    PROPERTIES ENVIRONMENT "COVOX_DATA_DIR=${COVOX_DATA_DIR}")
endfunction()
