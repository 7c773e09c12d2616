# Warnings and sanitizers applied to every ptmkit target through one interface library.
add_library(ptmkit_build_flags INTERFACE)
target_compile_options(ptmkit_build_flags INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow -Wconversion -Wno-sign-conversion
  -Wnon-virtual-dtor -Wold-style-cast -Woverloaded-virtual
  # No implicit a * b + c -> fma: the kernels compiled for FMA must give the bits of the
  # baseline ones (the 8-bit and float fit paths are tested to agree exactly).
  -ffp-contract=off)
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
if(PTMKIT_SANITIZE)
  target_compile_options(ptmkit_build_flags INTERFACE
    -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined)
  target_link_options(ptmkit_build_flags INTERFACE -fsanitize=address,undefined)
endif()
