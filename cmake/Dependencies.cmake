# Every third-party dependency, found from Debian 12 packages (scripts/install_deps.sh
# installs them). Each layer links only what it uses; LibTorch only in vision/ and avatar/.

find_package(Eigen3 3.3 REQUIRED NO_MODULE)
find_package(nlohmann_json 3 REQUIRED)

if(NOT HEADFORGE_SPLAT_ONLY)
  # COLMAP runs as a subprocess; its path is compiled in as the default.
  find_program(COLMAP_EXECUTABLE colmap REQUIRED)

  find_package(Boost 1.74 REQUIRED COMPONENTS program_options)
  find_package(OpenCV 4 REQUIRED COMPONENTS
    core imgproc imgcodecs videoio video dnn calib3d features2d quality photo)
  find_package(TinyGLTF REQUIRED)
  find_package(dlib REQUIRED)
  find_package(HDF5 REQUIRED COMPONENTS C CXX)
  find_package(Ceres 2 REQUIRED)
  find_package(OpenMesh REQUIRED CONFIG)
  find_package(tomlplusplus REQUIRED CONFIG)
endif()

# LibTorch. Where it was built with CUDA and a CUDA compiler is found, the
# rasterizer gets its CUDA kernels too (HEADFORGE_CUDA); Debian's LibTorch is
# CPU-only, and so is the build on it.
# LibTorch's CUDA set-up drops CMAKE_CUDA_ARCHITECTURES: keep the value given.
set(_cuda_architectures "${CMAKE_CUDA_ARCHITECTURES}")
if(NOT _cuda_architectures AND CMAKE_VERSION VERSION_GREATER_EQUAL 3.24)
  set(_cuda_architectures native)
endif()
find_package(Torch REQUIRED)
set(HEADFORGE_CUDA OFF)
if(TORCH_CUDA_LIBRARIES OR TARGET torch_cuda)
  include(CheckLanguage)
  check_language(CUDA)
  if(CMAKE_CUDA_COMPILER)
    enable_language(CUDA)
    find_package(CUDAToolkit REQUIRED)
    set(HEADFORGE_CUDA ON)
    set(HEADFORGE_CUDA_ARCHITECTURES "${_cuda_architectures}" CACHE STRING
        "CUDA architectures of the rasterizer's kernels")
    if(NOT HEADFORGE_CUDA_ARCHITECTURES)
      set(HEADFORGE_CUDA_ARCHITECTURES "75;80;90")
    endif()
    message(STATUS "HeadForge: CUDA rasterizer kernels for ${HEADFORGE_CUDA_ARCHITECTURES}")
  else()
    message(WARNING "LibTorch has CUDA but no CUDA compiler was found: the rasterizer is "
                    "built for the CPU only (set CMAKE_CUDA_COMPILER to add its CUDA kernels)")
  endif()
endif()
# at::parallel_for is a header template that runs serially unless its caller
# is compiled with OpenMP (LibTorch's CPU backend here is OpenMP).
find_package(OpenMP REQUIRED COMPONENTS CXX)
find_package(Threads REQUIRED)

if(HEADFORGE_BUILD_TESTS)
  find_package(GTest REQUIRED)
  if(NOT HEADFORGE_SPLAT_ONLY)
    find_package(rapidcheck REQUIRED CONFIG)
  endif()
endif()
if(HEADFORGE_BUILD_BENCHMARKS)
  find_package(benchmark REQUIRED)
endif()

if(NOT HEADFORGE_SPLAT_ONLY)
  # HDF5 as one imported target.
  add_library(headforge_hdf5 INTERFACE)
  target_include_directories(headforge_hdf5 SYSTEM INTERFACE ${HDF5_INCLUDE_DIRS})
  target_link_libraries(headforge_hdf5 INTERFACE ${HDF5_LIBRARIES} ${HDF5_CXX_LIBRARIES})
  target_compile_definitions(headforge_hdf5 INTERFACE ${HDF5_DEFINITIONS})
endif()

# LibTorch as one imported target, its compile flags (ABI) kept to its users.
add_library(headforge_torch INTERFACE)
target_link_libraries(headforge_torch INTERFACE ${TORCH_LIBRARIES} OpenMP::OpenMP_CXX)
target_include_directories(headforge_torch SYSTEM INTERFACE ${TORCH_INCLUDE_DIRS})
separate_arguments(_torch_flags UNIX_COMMAND "${TORCH_CXX_FLAGS}")
target_compile_options(headforge_torch INTERFACE ${_torch_flags})

# One precompiled <torch/torch.h>, reused by every LibTorch target (vision/,
# avatar/ and their tests).
add_library(headforge_torch_pch OBJECT ${PROJECT_SOURCE_DIR}/avatar/torch_pch.cc)
target_link_libraries(headforge_torch_pch PRIVATE headforge_torch headforge_warnings)
target_precompile_headers(headforge_torch_pch PRIVATE <torch/torch.h>)
function(headforge_reuse_torch_pch target)
  target_precompile_headers(${target} REUSE_FROM headforge_torch_pch)
endfunction()

# Where the dlib landmark model sits on Debian (package libdlib-data).
set(HEADFORGE_DLIB_LANDMARKS "/usr/share/dlib/shape_predictor_68_face_landmarks.dat"
    CACHE FILEPATH "Default 68-point landmark model")
