# Warning flags and per-target helpers shared by every HeadForge target.
add_library(headforge_warnings INTERFACE)
target_compile_options(headforge_warnings INTERFACE
  -Wall -Wextra -Wpedantic -Wno-unused-parameter)
if(HEADFORGE_ARCH)
  target_compile_options(headforge_warnings INTERFACE -march=${HEADFORGE_ARCH})
endif()

# headforge_add_test(NAME [WHOLE] [UNITY] SOURCES... LIBS... LABELS...): one gtest
# executable registered with ctest, a ctest entry per test case, or one entry
# for the whole executable with WHOLE (for suites sharing an expensive set-up,
# and for the unit binaries: a process per test case started each one's
# libraries again, 184 s for the unit tier against about 125 s whole; a
# failure names its test in the output all the same).
# Every test carries a tier label (ctest -L): unit (one module, seconds),
# integration (the real binary or several stages), colmap (runs COLMAP),
# train (trains a model), gpu (needs an NVIDIA GPU).
# FIGURES "Suite.Test:Suite.Other" names the test cases that check an
# accuracy figure on a benchmark's input rather than a mechanism: they take
# the label "figure" beside their tier ("integration-figure") and
# scripts/test.sh leaves them out unless asked (--figures).
function(headforge_add_test name)
  cmake_parse_arguments(ARG "WHOLE;UNITY" "FIGURES" "SOURCES;LIBS;LABELS;ARGS" ${ARGN})
  add_executable(${name} ${ARG_SOURCES})
  # Test files each keep their own helpers in an anonymous namespace; only
  # the binaries whose files are many and heavy (UNITY) are compiled in
  # batches (HEADFORGE_UNITY_BUILD).
  if(NOT ARG_UNITY)
    set_target_properties(${name} PROPERTIES UNITY_BUILD OFF)
  endif()
  target_link_libraries(${name} PRIVATE ${ARG_LIBS} GTest::gtest GTest::gtest_main headforge_warnings)
  target_compile_definitions(${name} PRIVATE
    HEADFORGE_TEST_SHARED_DATA="${HEADFORGE_SHARED_DATA}"
    HEADFORGE_TEST_BINARY_DIR="${CMAKE_BINARY_DIR}")
  if(NOT ARG_LABELS)
    message(FATAL_ERROR "headforge_add_test(${name}): give its LABELS (unit, integration, colmap, train, gpu)")
  endif()
  # OpenMP (OpenBLAS, Eigen, CHOLMOD, LibTorch) on one thread, as the command
  # line starts it: two tests run at once on two cores, and the Ceres stages'
  # small solves run several times slower threaded.
  # One label per test, its tiers joined by "-" ("integration-colmap"):
  # gtest_discover_tests cannot pass a list as a property's value, and ctest's
  # -L and -LE take regular expressions, so -L colmap and -LE train still pick.
  string(REPLACE ";" "-" label "${ARG_LABELS}")
  if(ARG_WHOLE)
    add_test(NAME ${name} COMMAND ${name} ${ARG_ARGS})
    set_tests_properties(${name} PROPERTIES LABELS "${label}" ENVIRONMENT "OMP_NUM_THREADS=1")
  elseif(ARG_FIGURES)
    gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 TEST_FILTER "-${ARG_FIGURES}"
      PROPERTIES LABELS "${label}" ENVIRONMENT "OMP_NUM_THREADS=1")
    gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 TEST_FILTER "${ARG_FIGURES}"
      PROPERTIES LABELS "${label}-figure" ENVIRONMENT "OMP_NUM_THREADS=1")
  else()
    gtest_discover_tests(${name} DISCOVERY_TIMEOUT 60 PROPERTIES LABELS "${label}" ENVIRONMENT "OMP_NUM_THREADS=1")
  endif()
endfunction()
