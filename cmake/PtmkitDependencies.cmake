# Every third-party dependency, found once, from Debian's packages (scripts/install-deps.sh).
find_package(Eigen3 3.4 REQUIRED NO_MODULE)
find_package(OpenImageIO REQUIRED)
find_package(PNG REQUIRED)
find_package(TIFF REQUIRED)
find_package(Threads REQUIRED)
find_package(TBB REQUIRED)
find_package(nlohmann_json 3.10 REQUIRED)
find_package(CLI11 REQUIRED)
find_package(Ceres REQUIRED)
find_package(OpenCV REQUIRED COMPONENTS core imgproc calib3d)
find_package(apriltag REQUIRED)
if(PTMKIT_BUILD_TESTS)
  find_package(GTest REQUIRED)
endif()
if(PTMKIT_BUILD_BENCH)
  find_package(benchmark REQUIRED)
endif()

# Adds a stage library and installs it: ptmkit_stage(NAME SOURCES ... PUBLIC_DEPS ...
# PRIVATE_DEPS ...). The target is ptmkit::NAME in the build and, after `cmake --install`,
# in `find_package(ptmkit COMPONENTS NAME)` (cmake/ptmkitConfig.cmake.in lists what each
# component needs).
function(ptmkit_stage name)
  cmake_parse_arguments(ARG "" "" "SOURCES;PUBLIC_DEPS;PRIVATE_DEPS" ${ARGN})
  add_library(ptmkit_${name} STATIC ${ARG_SOURCES})
  add_library(ptmkit::${name} ALIAS ptmkit_${name})
  set_target_properties(ptmkit_${name} PROPERTIES EXPORT_NAME ${name})
  target_include_directories(ptmkit_${name} PUBLIC
    $<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>
    $<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>)
  target_link_libraries(ptmkit_${name} PUBLIC ${ARG_PUBLIC_DEPS} PRIVATE ${ARG_PRIVATE_DEPS}
                        $<BUILD_INTERFACE:ptmkit_build_flags>)
  install(TARGETS ptmkit_${name} EXPORT ptmkit-${name}-targets
          ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
          LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR})
  install(DIRECTORY ${CMAKE_CURRENT_SOURCE_DIR}/include/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
  install(EXPORT ptmkit-${name}-targets NAMESPACE ptmkit::
          DESTINATION ${PTMKIT_INSTALL_CMAKEDIR})
endfunction()

# libjpeg (core: JPEG decoding; texture: the web export's planes) and cpp-httplib (apps: `ptmkit view`).
find_package(JPEG REQUIRED)
find_package(PkgConfig REQUIRED)
pkg_check_modules(HTTPLIB REQUIRED IMPORTED_TARGET cpp-httplib)

# MPI (Open MPI from Debian's libopenmpi-dev): `ptmkit fit` under mpirun/srun shares one
# capture among processes (docs/SCALE.md). Found at configure time unless PTMKIT_MPI=OFF; a
# build without it runs everything else and refuses a launch with several processes.
option(PTMKIT_MPI "Build `ptmkit fit`'s MPI support when MPI is found" ON)
set(PTMKIT_WITH_MPI OFF)
if(PTMKIT_MPI)
  find_package(MPI COMPONENTS C QUIET)
  if(MPI_C_FOUND)
    set(PTMKIT_WITH_MPI ON)
  endif()
endif()
message(STATUS "ptmkit: MPI support ${PTMKIT_WITH_MPI}")
