# Warnings and sanitizers applied to every ptmkit target through one interface library. It is
# linked as $<BUILD_INTERFACE:...>: an installed ptmkit does not impose its warnings on users.
# Floating-point contraction is set where results must be bit-exact (fit/CMakeLists.txt).
add_library(ptmkit_build_flags INTERFACE)
target_compile_options(ptmkit_build_flags INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wno-sign-conversion
  -Wnon-virtual-dtor -Wold-style-cast -Woverloaded-virtual)
if(PTMKIT_NATIVE)
  target_compile_options(ptmkit_build_flags INTERFACE -march=native)
endif()
if(PTMKIT_FUZZ)
  # The fuzz targets link libFuzzer's main. Coverage is instrumented only where the parsers
  # are (ptmkit_fuzz_coverage below): it slows every comparison, and the sanitizer test suite
  # runs from this same build.
  target_compile_options(ptmkit_build_flags INTERFACE
    -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined)
  target_link_options(ptmkit_build_flags INTERFACE -fsanitize=address,undefined)
endif()
if(PTMKIT_SANITIZE OR PTMKIT_FUZZ)
  # Line tables are all a sanitizer report needs, and cost a fraction of full debug info to
  # build (-g1, line tables, overrides RelWithDebInfo's -g under gcc and clang alike).
  target_compile_options(ptmkit_build_flags INTERFACE -g1)
endif()

# ptmkit_fuzz_coverage(TARGET [SOURCE...]): with PTMKIT_FUZZ, instruments TARGET (or only the
# listed sources of it) for libFuzzer's coverage guidance.
function(ptmkit_fuzz_coverage target)
  if(NOT PTMKIT_FUZZ)
    return()
  endif()
  if(ARGN)
    set_property(SOURCE ${ARGN} TARGET_DIRECTORY ${target} APPEND PROPERTY COMPILE_OPTIONS
                 -fsanitize=fuzzer-no-link)
  else()
    target_compile_options(${target} PRIVATE -fsanitize=fuzzer-no-link)
  endif()
endfunction()
if(PTMKIT_SANITIZE OR PTMKIT_FUZZ)
  # One name for "built with AddressSanitizer" under gcc (__SANITIZE_ADDRESS__) and clang
  # (__has_feature), for code and tests that must behave differently there.
  target_compile_definitions(ptmkit_build_flags INTERFACE PTMKIT_ASAN=1)
endif()
if(PTMKIT_SANITIZE)
  target_compile_options(ptmkit_build_flags INTERFACE
    -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined)
  target_link_options(ptmkit_build_flags INTERFACE -fsanitize=address,undefined)
endif()
