/* The true decode floor of a JPEG capture: every image of a light file decoded with
 * libjpeg(-turbo) alone, default settings (accurate integer IDCT, fancy upsampling, as
 * ptmkit's reader), on T threads (each decodes whole images, the next one in the light file's
 * order), rows discarded. Nothing but libjpeg and libc is linked: the floor that `ptmkit fit`
 * is measured against (scripts/bench-fit.sh, docs/PERFORMANCE.md).
 * Usage: jpeg_floor LIGHTS.lp [THREADS] */
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include <jpeglib.h>

#define MAX_IMAGES 4096

static char* g_paths[MAX_IMAGES];
static int g_count;
static atomic_int g_next;
static atomic_ulong g_checksum;

static void* worker(void* arg) {
  (void)arg;
  for (;;) {
    const int i = atomic_fetch_add(&g_next, 1);
    if (i >= g_count) return NULL;
    FILE* f = fopen(g_paths[i], "rb");
    if (f == NULL) {
      fprintf(stderr, "jpeg_floor: cannot open %s\n", g_paths[i]);
      exit(1);
    }
    struct jpeg_decompress_struct cinfo;
    struct jpeg_error_mgr err;
    cinfo.err = jpeg_std_error(&err);
    jpeg_create_decompress(&cinfo);
    jpeg_stdio_src(&cinfo, f);
    jpeg_read_header(&cinfo, TRUE);
    cinfo.out_color_space = cinfo.num_components == 1 ? JCS_GRAYSCALE : JCS_RGB;
    jpeg_start_decompress(&cinfo);
    const size_t stride = (size_t)cinfo.output_width * (size_t)cinfo.output_components;
    unsigned char* rows = malloc(stride * 16);
    JSAMPROW ptrs[16];
    for (int r = 0; r < 16; ++r) ptrs[r] = rows + stride * (size_t)r;
    unsigned long sum = 0;
    while (cinfo.output_scanline < cinfo.output_height) {
      const JDIMENSION n = jpeg_read_scanlines(&cinfo, ptrs, 16);
      sum += rows[(stride / 2) * (n > 0 ? 1 : 0)];
    }
    jpeg_finish_decompress(&cinfo);
    jpeg_destroy_decompress(&cinfo);
    free(rows);
    fclose(f);
    atomic_fetch_add(&g_checksum, sum);
  }
}

int main(int argc, char** argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: jpeg_floor LIGHTS.lp [THREADS]\n");
    return 2;
  }
  const int threads = argc > 2 && atoi(argv[2]) > 0 ? atoi(argv[2]) : 2;
  struct timespec t0, t1;
  clock_gettime(CLOCK_MONOTONIC, &t0);
  FILE* lp = fopen(argv[1], "r");
  if (lp == NULL) {
    fprintf(stderr, "jpeg_floor: cannot open %s\n", argv[1]);
    return 1;
  }
  /* Folder of the light file: image names are relative to it. */
  char dir[4096];
  snprintf(dir, sizeof(dir), "%s", argv[1]);
  char* slash = strrchr(dir, '/');
  if (slash != NULL)
    slash[1] = '\0';
  else
    dir[0] = '\0';
  char line[8192];
  while (fgets(line, sizeof(line), lp) != NULL && g_count < MAX_IMAGES) {
    char name[4096];
    double x, y, z;
    if (sscanf(line, "%4095s %lf %lf %lf", name, &x, &y, &z) != 4) continue; /* count line */
    const size_t n = strlen(dir) + strlen(name) + 1;
    g_paths[g_count] = malloc(n);
    snprintf(g_paths[g_count], n, "%s%s", name[0] == '/' ? "" : dir, name);
    ++g_count;
  }
  fclose(lp);
  pthread_t tids[64];
  const int nt = threads < 64 ? threads : 64;
  for (int t = 0; t < nt; ++t) pthread_create(&tids[t], NULL, worker, NULL);
  for (int t = 0; t < nt; ++t) pthread_join(tids[t], NULL);
  clock_gettime(CLOCK_MONOTONIC, &t1);
  const double s = (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec);
  printf("libjpeg alone: %d images in %.3f s on %d threads (checksum %lu)\n", g_count, s, nt,
         (unsigned long)atomic_load(&g_checksum));
  return 0;
}
