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
  # Every library instrumented for coverage; the fuzz targets link libFuzzer's main.
  target_compile_options(ptmkit_build_flags INTERFACE
    -fsanitize=fuzzer-no-link,address,undefined -fno-omit-frame-pointer
    -fno-sanitize-recover=undefined -g)
  target_link_options(ptmkit_build_flags INTERFACE -fsanitize=address,undefined)
endif()
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
