/* A capture of any size for the memory and scale benchmarks, rendered row by row so that its
 * own memory stays a few rows whatever the size (`ptmkit synth` holds whole images: a
 * 16000 x 16000 render would need tens of gigabytes). The scene: a Lambertian relief (a sum
 * of sines, analytic normals) with a varying albedo and a little deterministic noise, lit
 * from the light file's directions, written as 8-bit sRGB-coded JPEG (quality Q), one file per
 * light named as in a light file that it writes beside them.
 * Usage: make_large_stack OUT_DIR WIDTH HEIGHT LIGHTS_LP_IN [QUALITY] [THREADS]
 *   LIGHTS_LP_IN: a light file whose directions are used (e.g. from `ptmkit synth --lights
 *   dome49 --size 8`); OUT_DIR/lights.lp lists the new images with the same directions. */
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <jpeglib.h>

#define MAX_LIGHTS 1024

static double g_dir[MAX_LIGHTS][3];
static int g_lights;
static int g_width, g_height, g_quality;
static const char* g_out;
static atomic_int g_next;

static uint32_t hash3(uint32_t x, uint32_t y, uint32_t z) {
  uint32_t h = x * 0x8da6b343u ^ y * 0xd8163841u ^ z * 0xcb1ab31fu;
  h ^= h >> 13;
  h *= 0x5bd1e995u;
  return h ^ (h >> 15);
}

static void render(int light) {
  char path[4096];
  snprintf(path, sizeof path, "%s/image_%03d.jpg", g_out, light + 1);
  FILE* f = fopen(path, "wb");
  if (f == NULL) {
    fprintf(stderr, "make_large_stack: cannot write %s\n", path);
    exit(1);
  }
  struct jpeg_compress_struct c;
  struct jpeg_error_mgr err;
  c.err = jpeg_std_error(&err);
  jpeg_create_compress(&c);
  jpeg_stdio_dest(&c, f);
  c.image_width = (JDIMENSION)g_width;
  c.image_height = (JDIMENSION)g_height;
  c.input_components = 3;
  c.in_color_space = JCS_RGB;
  jpeg_set_defaults(&c);
  jpeg_set_quality(&c, g_quality, TRUE);
  jpeg_start_compress(&c, TRUE);
  unsigned char* row = malloc((size_t)g_width * 3);
  /* Per column: the x factors of the normal and the albedo (separable sines), so a pixel
   * costs a few products, a square root and a table lookup. */
  double* sx = malloc(sizeof(double) * (size_t)g_width * 5);
  double *cx = sx + g_width, *sa = cx + g_width, *ca = sa + g_width, *cc = ca + g_width;
  const double* l = g_dir[light];
  const double kx = 2.0 * M_PI / 173.0, ky = 2.0 * M_PI / 229.0, amp = 9.0;
  for (int x = 0; x < g_width; ++x) {
    sx[x] = sin(kx * x);
    cx[x] = cos(kx * x);
    sa[x] = sin(0.0041 * x);
    ca[x] = cos(0.0041 * x);
    cc[x] = cos(0.0023 * x);
  }
  /* Display coding of a linear value in [0, 1): 4096 steps. */
  static const int kSteps = 4096;
  unsigned char* to_srgb = malloc((size_t)kSteps);
  for (int i = 0; i < kSteps; ++i)
    to_srgb[i] = (unsigned char)(255.0 * pow((i + 0.5) / kSteps, 1.0 / 2.2) + 0.5);
  const double tint[3] = {1.0, 0.86, 0.7};
  for (int y = 0; y < g_height; ++y) {
    const double sy = sin(ky * y), cy = cos(ky * y);
    const double sb = sin(0.0057 * y), cb = cos(0.0057 * y);
    for (int x = 0; x < g_width; ++x) {
      /* h = amp sin(kx x) sin(ky y): the normal from its gradient. */
      const double hx = amp * kx * cx[x] * sy, hy = amp * ky * sx[x] * cy;
      const double inv = 1.0 / sqrt(hx * hx + hy * hy + 1.0);
      double shade = (-hx * l[0] - hy * l[1] + l[2]) * inv;
      if (shade < 0.0) shade = 0.0;
      const double albedo = 0.55 + 0.35 * (sa[x] * cb + ca[x] * sb) * cc[x];
      const uint32_t h = hash3((uint32_t)x, (uint32_t)y, (uint32_t)light);
      /* Sensor-like noise, +-5 grey levels: real quality-95 captures are 2-2.5 bits a pixel,
       and a noiseless render would compress (and decode) far more cheaply. */
      const int noise = (int)(h % 11u) - 5;
      for (int ch = 0; ch < 3; ++ch) {
        const double lin = albedo * tint[ch] * shade * 0.9;
        int v = to_srgb[(int)(lin * kSteps)] + noise;
        v = v < 0 ? 0 : v > 255 ? 255 : v;
        row[3 * x + ch] = (unsigned char)v;
      }
    }
    JSAMPROW rows[1] = {row};
    jpeg_write_scanlines(&c, rows, 1);
  }
  free(to_srgb);
  free(sx);
  jpeg_finish_compress(&c);
  jpeg_destroy_compress(&c);
  free(row);
  if (fclose(f) != 0) {
    fprintf(stderr, "make_large_stack: write failed: %s\n", path);
    exit(1);
  }
}

static void* worker(void* arg) {
  (void)arg;
  for (;;) {
    const int i = atomic_fetch_add(&g_next, 1);
    if (i >= g_lights) return NULL;
    render(i);
  }
}

int main(int argc, char** argv) {
  if (argc < 5) {
    fprintf(stderr,
            "usage: make_large_stack OUT_DIR WIDTH HEIGHT LIGHTS_LP_IN [QUALITY] [THREADS]\n");
    return 2;
  }
  g_out = argv[1];
  g_width = atoi(argv[2]);
  g_height = atoi(argv[3]);
  g_quality = argc > 5 ? atoi(argv[5]) : 95;
  const int threads = argc > 6 ? atoi(argv[6]) : 2;
  if (g_width < 1 || g_height < 1 || g_quality < 1 || g_quality > 100 || threads < 1) {
    fprintf(stderr, "make_large_stack: bad size, quality or threads\n");
    return 2;
  }
  FILE* in = fopen(argv[4], "r");
  if (in == NULL) {
    fprintf(stderr, "make_large_stack: cannot read %s\n", argv[4]);
    return 1;
  }
  if (fscanf(in, "%d", &g_lights) != 1 || g_lights < 1 || g_lights > MAX_LIGHTS) {
    fprintf(stderr, "make_large_stack: %s: bad light count\n", argv[4]);
    return 1;
  }
  char name[4096];
  for (int i = 0; i < g_lights; ++i) {
    if (fscanf(in, "%4095s %lf %lf %lf", name, &g_dir[i][0], &g_dir[i][1], &g_dir[i][2]) != 4) {
      fprintf(stderr, "make_large_stack: %s: bad light %d\n", argv[4], i + 1);
      return 1;
    }
  }
  fclose(in);
  char lp[4096];
  snprintf(lp, sizeof lp, "%s/lights.lp", g_out);
  FILE* out = fopen(lp, "w");
  if (out == NULL) {
    fprintf(stderr, "make_large_stack: cannot write %s\n", lp);
    return 1;
  }
  fprintf(out, "%d\n", g_lights);
  for (int i = 0; i < g_lights; ++i) {
    fprintf(out, "image_%03d.jpg %.9f %.9f %.9f\n", i + 1, g_dir[i][0], g_dir[i][1], g_dir[i][2]);
  }
  fclose(out);
  pthread_t t[64];
  const int n = threads < 64 ? threads : 64;
  for (int i = 0; i < n; ++i) pthread_create(&t[i], NULL, worker, NULL);
  for (int i = 0; i < n; ++i) pthread_join(t[i], NULL);
  return 0;
}
