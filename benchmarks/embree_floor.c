/* The floor of a ray query on this machine: Embree 4's closest-hit calls from C, nothing else.

   benchmarks/embree_floor.py writes a batch file (the scene's triangles and a batch of rays), builds this
   program against the libembree4 that embreex's wheel bundles (which ships no headers: the few declarations
   below follow Embree 4's public headers rtcore_common.h, rtcore_device.h, rtcore_scene.h, rtcore_geometry.h,
   rtcore_ray.h), and runs it. It builds the scene twice from one triangle geometry (float32 vertices):
   "robust" as the toolkit builds it (RTC_SCENE_FLAG_ROBUST, the default build quality), and "fast" as
   Mitsuba 3 builds its own (no scene flags, RTC_BUILD_QUALITY_HIGH). In each it traces every ray of the
   batch with rtcIntersect1, and with rtcIntersect8 and rtcIntersect16 both without and with
   RTC_RAY_QUERY_FLAG_COHERENT (the flag Mitsuba passes for camera rays), on 1 to THREADS_MAX threads (each
   thread a contiguous share of the batch), rays as the toolkit asks for them (tnear 0, tfar 1e37). It prints
   one line per configuration and thread count, "scene width coherent threads wall_ns cpu_ns": per ray, the
   wall clock and the process's CPU time over the batch (on a shared machine the CPU time is the cost of the
   work; the wall time adds the waits for a core). Per ray it does what any renderer must: copy the ray in,
   call Embree, copy distance and primitive out. With a third argument it writes each configuration's
   answers there, in the order of the lines printed (float32 tfar, then int32 primID, -1 for a miss; n values
   each), for the agreement test.

   usage: embree_floor BATCH THREADS_MAX [HITS_OUT]

   BATCH: int32 nv, nt, n; float32 vertices[nv][3]; uint32 triangles[nt][3]; float32 org[n][3], dir[n][3].
*/
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>
#include <time.h>

/* --- Embree 4's API, as declared in its headers (the subset used here) ----------------------------------- */
typedef void *RTCDevice, *RTCScene, *RTCGeometry;
enum { RTC_GEOMETRY_TYPE_TRIANGLE = 0, RTC_BUFFER_TYPE_INDEX = 0, RTC_BUFFER_TYPE_VERTEX = 1 };
enum { RTC_FORMAT_UINT3 = 0x5003, RTC_FORMAT_FLOAT3 = 0x9003 };
enum { RTC_SCENE_FLAG_NONE = 0, RTC_SCENE_FLAG_ROBUST = 1 << 2 };
enum { RTC_BUILD_QUALITY_MEDIUM = 1, RTC_BUILD_QUALITY_HIGH = 2 };
enum { RTC_RAY_QUERY_FLAG_INCOHERENT = 0 << 16, RTC_RAY_QUERY_FLAG_COHERENT = 1 << 16 };
#define RTC_FEATURE_FLAG_ALL 0xffffffffu
enum { RTC_DEVICE_PROPERTY_VERSION = 0, RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED = 33,
       RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED = 34 };
#define RTC_INVALID_GEOMETRY_ID 0xFFFFFFFFu
#define RTC_MAX_INSTANCE_LEVEL_COUNT 1

RTCDevice rtcNewDevice(const char *config);
ssize_t rtcGetDeviceProperty(RTCDevice device, int prop);
RTCScene rtcNewScene(RTCDevice device);
void rtcSetSceneFlags(RTCScene scene, int flags);
void rtcSetSceneBuildQuality(RTCScene scene, int quality);
RTCGeometry rtcNewGeometry(RTCDevice device, int type);
void *rtcSetNewGeometryBuffer(RTCGeometry geometry, int type, unsigned int slot, int format, size_t byteStride,
                              size_t itemCount);
void rtcCommitGeometry(RTCGeometry geometry);
unsigned int rtcAttachGeometry(RTCScene scene, RTCGeometry geometry);
void rtcReleaseGeometry(RTCGeometry geometry);
void rtcCommitScene(RTCScene scene);
void rtcReleaseScene(RTCScene scene);
void rtcReleaseDevice(RTCDevice device);

/* RTCRayHit: RTCRay (org, tnear, dir, time, tfar, mask, id, flags), then RTCHit (Ng, u, v, primID, geomID,
   instID, instPrimID). The packets are the same fields as structures of arrays, N lanes each, aligned to
   4N bytes. Embree writes no field past instPrimID, whichever instancing options it was built with. */
struct __attribute__((aligned(16))) RTCRayHit {
  float org_x, org_y, org_z, tnear, dir_x, dir_y, dir_z, time, tfar;
  unsigned int mask, id, flags;
  float Ng_x, Ng_y, Ng_z, u, v;
  unsigned int primID, geomID, instID[RTC_MAX_INSTANCE_LEVEL_COUNT], instPrimID[RTC_MAX_INSTANCE_LEVEL_COUNT];
};
#define RAYHIT_PACKET(N)                                                                                       \
  struct __attribute__((aligned(4 * N))) RTCRayHit##N {                                                        \
    float org_x[N], org_y[N], org_z[N], tnear[N], dir_x[N], dir_y[N], dir_z[N], time[N], tfar[N];              \
    unsigned int mask[N], id[N], flags[N];                                                                     \
    float Ng_x[N], Ng_y[N], Ng_z[N], u[N], v[N];                                                               \
    unsigned int primID[N], geomID[N], instID[RTC_MAX_INSTANCE_LEVEL_COUNT][N],                                \
        instPrimID[RTC_MAX_INSTANCE_LEVEL_COUNT][N];                                                           \
  };
RAYHIT_PACKET(8)
RAYHIT_PACKET(16)

/* RTCIntersectArguments as rtcInitIntersectArguments fills it (an inline function of the header, so not in
   the library), the flags aside; the last field exists only in builds with RTC_MIN_WIDTH, and is 0 there.
   The toolkit's kernels pass NULL: Embree's defaults, which are these with the incoherent flag. */
struct __attribute__((aligned(16))) RTCIntersectArguments {
  int flags, feature_mask;
  void *context, *filter, *intersect;
  float minWidthDistanceFactor;
};
void rtcIntersect1(RTCScene scene, struct RTCRayHit *rayhit, const struct RTCIntersectArguments *args);
void rtcIntersect8(const int *valid, RTCScene scene, struct RTCRayHit8 *rayhit,
                   const struct RTCIntersectArguments *args);
void rtcIntersect16(const int *valid, RTCScene scene, struct RTCRayHit16 *rayhit,
                    const struct RTCIntersectArguments *args);

/* --- the batch ------------------------------------------------------------------------------------------- */
#define NO_TFAR 1e37f /* the toolkit's tfar of a closest-hit query */

typedef struct {
  RTCScene scene;
  const float *org, *dir; /* n x 3 */
  float *tfar;            /* n: hit distance, NO_TFAR on a miss */
  int32_t *prim;          /* n: primitive id, -1 on a miss */
  size_t first, last;     /* this thread's rays */
  int width;
  const struct RTCIntersectArguments *args;
} Work;

static void trace1(const Work *w) {
  struct RTCRayHit rh;
  for (size_t i = w->first; i < w->last; i++) {
    const float *o = w->org + 3 * i, *d = w->dir + 3 * i;
    rh.org_x = o[0], rh.org_y = o[1], rh.org_z = o[2], rh.tnear = 0.0f;
    rh.dir_x = d[0], rh.dir_y = d[1], rh.dir_z = d[2], rh.time = 0.0f;
    rh.tfar = NO_TFAR, rh.mask = 0xFFFFFFFFu, rh.id = 0, rh.flags = 0;
    rh.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(w->scene, &rh, w->args);
    w->tfar[i] = rh.tfar;
    w->prim[i] = rh.geomID == RTC_INVALID_GEOMETRY_ID ? -1 : (int32_t)rh.primID;
  }
}

/* One packet width's loop: fill the lanes, mark the tail's unused lanes invalid, call, copy out. */
#define TRACE_PACKETS(N)                                                                                       \
  static void trace##N(const Work *w) {                                                                        \
    struct RTCRayHit##N rh;                                                                                    \
    int valid[N] __attribute__((aligned(4 * N)));                                                              \
    memset(&rh, 0, sizeof rh);                                                                                 \
    for (size_t first = w->first; first < w->last; first += N) {                                               \
      size_t n = w->last - first < N ? w->last - first : N;                                                    \
      for (size_t k = 0; k < N; k++) {                                                                         \
        valid[k] = k < n ? -1 : 0;                                                                             \
        if (k >= n) continue;                                                                                  \
        const float *o = w->org + 3 * (first + k), *d = w->dir + 3 * (first + k);                             \
        rh.org_x[k] = o[0], rh.org_y[k] = o[1], rh.org_z[k] = o[2], rh.tnear[k] = 0.0f;                        \
        rh.dir_x[k] = d[0], rh.dir_y[k] = d[1], rh.dir_z[k] = d[2], rh.time[k] = 0.0f;                         \
        rh.tfar[k] = NO_TFAR, rh.mask[k] = 0xFFFFFFFFu, rh.id[k] = 0, rh.flags[k] = 0;                         \
        rh.geomID[k] = RTC_INVALID_GEOMETRY_ID;                                                                \
      }                                                                                                        \
      rtcIntersect##N(valid, w->scene, &rh, w->args);                                                          \
      for (size_t k = 0; k < n; k++) {                                                                         \
        w->tfar[first + k] = rh.tfar[k];                                                                       \
        w->prim[first + k] = rh.geomID[k] == RTC_INVALID_GEOMETRY_ID ? -1 : (int32_t)rh.primID[k];           \
      }                                                                                                        \
    }                                                                                                          \
  }
TRACE_PACKETS(8)
TRACE_PACKETS(16)

static void *run(void *arg) {
  const Work *w = arg;
  if (w->width == 1) trace1(w);
  else if (w->width == 8) trace8(w);
  else trace16(w);
  return NULL;
}

static double now(clockid_t clock) {
  struct timespec t;
  clock_gettime(clock, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

/* Wall and CPU seconds to trace rays 0 .. n-1 at this width on `threads` threads, each a contiguous share. */
static void trace(RTCScene scene, const struct RTCIntersectArguments *args, const float *org, const float *dir,
                  size_t n, int width, int threads, float *tfar, int32_t *prim, double seconds[2]) {
  pthread_t ids[64];
  Work work[64];
  double t0 = now(CLOCK_MONOTONIC), c0 = now(CLOCK_PROCESS_CPUTIME_ID);
  for (int k = 0; k < threads; k++) {
    work[k] = (Work){scene, org, dir, tfar, prim, n * k / threads, n * (k + 1) / threads, width, args};
    if (pthread_create(&ids[k], NULL, run, &work[k]) != 0) {
      fprintf(stderr, "embree_floor: pthread_create failed\n");
      exit(1);
    }
  }
  for (int k = 0; k < threads; k++) pthread_join(ids[k], NULL);
  seconds[0] = now(CLOCK_MONOTONIC) - t0, seconds[1] = now(CLOCK_PROCESS_CPUTIME_ID) - c0;
}

static void *read_exactly(FILE *f, size_t bytes, const char *what) {
  void *p = aligned_alloc(64, bytes + 64);
  if (p == NULL || fread(p, 1, bytes, f) != bytes) {
    fprintf(stderr, "embree_floor: the batch file ends before its %s\n", what);
    exit(2);
  }
  return p;
}

int main(int argc, char **argv) {
  if (argc < 3 || argc > 4) {
    fprintf(stderr, "usage: embree_floor BATCH THREADS_MAX [HITS_OUT]\n");
    return 2;
  }
  int threads_max = atoi(argv[2]);
  if (threads_max < 1 || threads_max > 64) {
    fprintf(stderr, "embree_floor: THREADS_MAX must be 1 .. 64, got %s\n", argv[2]);
    return 2;
  }
  FILE *f = fopen(argv[1], "rb");
  if (f == NULL) {
    fprintf(stderr, "embree_floor: cannot open %s\n", argv[1]);
    return 2;
  }
  int32_t *head = read_exactly(f, 3 * sizeof(int32_t), "header");
  size_t nv = (size_t)head[0], nt = (size_t)head[1], n = (size_t)head[2];
  float *vertices = read_exactly(f, nv * 12, "vertices");
  uint32_t *triangles = read_exactly(f, nt * 12, "triangles");
  float *org = read_exactly(f, n * 12, "ray origins");
  float *dir = read_exactly(f, n * 12, "ray directions");
  fclose(f);

  RTCDevice device = rtcNewDevice(NULL);
  const char *names[2] = {"robust", "fast"};
  RTCScene scenes[2];
  for (int k = 0; k < 2; k++) {
    scenes[k] = rtcNewScene(device);
    /* robust: the toolkit's scene (and embreex's); fast: Mitsuba 3's (its scene_embree.inl) */
    rtcSetSceneFlags(scenes[k], k == 0 ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
    rtcSetSceneBuildQuality(scenes[k], k == 0 ? RTC_BUILD_QUALITY_MEDIUM : RTC_BUILD_QUALITY_HIGH);
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    memcpy(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, nv), vertices, nv * 12);
    memcpy(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, nt), triangles, nt * 12);
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scenes[k], geom);
    rtcReleaseGeometry(geom);
    rtcCommitScene(scenes[k]);
  }
  printf("embree %zd native8 %zd native16 %zd rays %zu\n", rtcGetDeviceProperty(device, RTC_DEVICE_PROPERTY_VERSION),
         rtcGetDeviceProperty(device, RTC_DEVICE_PROPERTY_NATIVE_RAY8_SUPPORTED),
         rtcGetDeviceProperty(device, RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED), n);

  float *tfar = aligned_alloc(64, n * 4 + 64);
  int32_t *prim = aligned_alloc(64, n * 4 + 64);
  FILE *out = argc == 4 ? fopen(argv[3], "wb") : NULL;
  if (argc == 4 && out == NULL) {
    fprintf(stderr, "embree_floor: cannot write %s\n", argv[3]);
    return 2;
  }
  struct RTCIntersectArguments args[2];
  for (int c = 0; c < 2; c++) {
    memset(&args[c], 0, sizeof args[c]);
    args[c].flags = c ? RTC_RAY_QUERY_FLAG_COHERENT : RTC_RAY_QUERY_FLAG_INCOHERENT;
    args[c].feature_mask = (int)RTC_FEATURE_FLAG_ALL;
  }
  double s[2];
  trace(scenes[0], &args[0], org, dir, n, 1, 1, tfar, prim, s); /* untimed: every buffer's pages touched once */
  const int widths[5] = {1, 8, 8, 16, 16}, coherent[5] = {0, 0, 1, 0, 1};
  for (int k = 0; k < 2; k++) {
    for (int c = 0; c < 5; c++) {
      for (int threads = 1; threads <= threads_max; threads++) {
        trace(scenes[k], &args[coherent[c]], org, dir, n, widths[c], threads, tfar, prim, s);
        printf("%s %d %d %d %.3f %.3f\n", names[k], widths[c], coherent[c], threads, s[0] / (double)n * 1e9,
               s[1] / (double)n * 1e9);
      }
      if (out != NULL && (fwrite(tfar, 4, n, out) != n || fwrite(prim, 4, n, out) != n)) {
        fprintf(stderr, "embree_floor: cannot write %s\n", argv[3]);
        return 1;
      }
    }
    rtcReleaseScene(scenes[k]);
  }
  if (out != NULL) fclose(out);
  rtcReleaseDevice(device);
  return 0;
}
