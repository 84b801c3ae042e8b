/* Our path tracer's estimator, compiled from C: what a compiled kernel would buy over numba.

   benchmarks/pathtracer_c.py exports a scene as the toolkit builds it (SceneGeometry's tables, the camera
   basis, the sample dimensions, roulette and unit sizes), builds this program with cc against the libembree4
   embreex bundles (declarations as in embree_floor.c) and runs it. It renders as
   cornell_harness.renderers.pathtracer does with sampler = independent, operation for operation in float64,
   so each path's estimate is our numba kernel's to the bit (the driver checks it): the same work unit
   wavefront (camera rays; per bounce closest hits, shading, NEE shadow segments), the same 8-wide incoherent
   packets (rtcIntersect8 / rtcOccluded8: the fastest call for bounce rays, BENCHMARKS.md's floor), the same
   counter-based random numbers (core/rng.py). Lambertian triangles only (the driver refuses other scenes).
   Threads take work units from one counter; each sums into its own film.

   QUERIES: "toolkit" asks Embree as the toolkit does (robust scene, default arguments); "mitsuba" as Mitsuba 3
   does (no scene flags, high build quality, the coherent flag on camera rays), to see what the queries'
   configuration costs; its hits may differ at grazing edges, so its estimates are not checked bit for bit.

   usage: pathtracer_c SCENE QUERIES render THREADS CLOCK_QUERIES SUMS_OUT
            every pass; prints "threads paths rays wall_s cpu_s query_cpu_s" (query time with CLOCK_QUERIES 1:
            each batch query on its thread's CPU clock) and writes the film's per-pixel sums and sums of
            squares (float64, pixels x 3 each).
          pathtracer_c SCENE QUERIES paths PASS FIRST STOP ESTIMATES_OUT
            the estimates (float64 x 3) of paths FIRST .. STOP-1 of pass PASS, traced as one work unit.
*/
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/types.h>
#include <time.h>

/* --- Embree 4's API, the subset used (its public headers rtcore_*.h) ------------------------------------- */
typedef void *RTCDevice, *RTCScene, *RTCGeometry;
enum { RTC_GEOMETRY_TYPE_TRIANGLE = 0, RTC_BUFFER_TYPE_INDEX = 0, RTC_BUFFER_TYPE_VERTEX = 1 };
enum { RTC_FORMAT_UINT3 = 0x5003, RTC_FORMAT_FLOAT3 = 0x9003, RTC_SCENE_FLAG_ROBUST = 1 << 2 };
enum { RTC_BUILD_QUALITY_HIGH = 2, RTC_RAY_QUERY_FLAG_COHERENT = 1 << 16 };
#define RTC_INVALID_GEOMETRY_ID 0xFFFFFFFFu
RTCDevice rtcNewDevice(const char *config);
ssize_t rtcGetDeviceProperty(RTCDevice device, int prop);
RTCScene rtcNewScene(RTCDevice device);
void rtcSetSceneFlags(RTCScene scene, int flags);
void rtcSetSceneBuildQuality(RTCScene scene, int quality);
RTCGeometry rtcNewGeometry(RTCDevice device, int type);
void *rtcSetNewGeometryBuffer(RTCGeometry g, int type, unsigned slot, int format, size_t stride, size_t count);
void rtcCommitGeometry(RTCGeometry geometry);
unsigned int rtcAttachGeometry(RTCScene scene, RTCGeometry geometry);
void rtcReleaseGeometry(RTCGeometry geometry);
void rtcCommitScene(RTCScene scene);
/* RTCRayHit8: the ray's fields, then the hit's, 8 lanes each; rtcOccluded8 reads the ray part (RTCRay8). */
struct __attribute__((aligned(32))) RTCRayHit8 {
  float org_x[8], org_y[8], org_z[8], tnear[8], dir_x[8], dir_y[8], dir_z[8], time[8], tfar[8];
  unsigned int mask[8], id[8], flags[8];
  float Ng_x[8], Ng_y[8], Ng_z[8], u[8], v[8];
  unsigned int primID[8], geomID[8], instID[1][8], instPrimID[1][8];
};
/* RTCIntersectArguments as rtcInitIntersectArguments fills it (embree_floor.c); NULL: Embree's defaults
   (incoherent), what the toolkit's kernels pass. */
struct __attribute__((aligned(16))) RTCIntersectArguments {
  int flags, feature_mask;
  void *context, *filter, *intersect;
  float minWidthDistanceFactor;
};
void rtcIntersect8(const int *valid, RTCScene scene, struct RTCRayHit8 *rh, const struct RTCIntersectArguments *a);
void rtcOccluded8(const int *valid, RTCScene scene, struct RTCRayHit8 *ray, const void *args);

/* --- the scene, as the driver exports it ------------------------------------------------------------------ */
enum { NV, NT, NE, WIDTH, HEIGHT, MAX_DEPTH, RR_DEPTH, PASSES, MIN_UNIT, MAX_UNIT, DIM_CAMERA, DIM_VERTEX,
       VERTEX_STRIDE, OFF_PICK, OFF_LIGHT, OFF_BSDF, OFF_ROULETTE, HEADER_INTS };
typedef struct {
  int32_t h[HEADER_INTS];
  double offset, q_max, shadow_tfar_rel, basis[12]; /* basis: camera position, right, up, forward */
  double *v0, *e1, *e2, *normal, *rho, *radiance, *pdf_area, *cdf; /* per triangle (x3); cdf per emitter */
  int64_t *emitters, *pass_paths;
  uint64_t *keys; /* per pass: the independent stream's key */
  RTCScene scene;
  const struct RTCIntersectArguments *camera_args; /* NULL, or coherent (QUERIES mitsuba) */
} Scene;

typedef struct { double x, y, z; } V;
static inline V v3(const double *a, int64_t i) { return (V){a[3 * i], a[3 * i + 1], a[3 * i + 2]}; }
static inline V mad(V a, double s, V b) { return (V){a.x + s * b.x, a.y + s * b.y, a.z + s * b.z}; }
static inline double dot(V a, V b) { return a.x * b.x + a.y * b.y + a.z * b.z; }

/* core/rng.py: uniform(key, path, dim), the SplitMix64 finaliser applied twice. */
static inline uint64_t mix64(uint64_t z) {
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}
static inline double uniform(uint64_t key, uint64_t path, uint64_t dim) {
  uint64_t z = mix64(key ^ mix64(((path << 24) | dim) * 0x9E3779B97F4A7C15ull));
  return (double)(z >> 11) * (1.0 / 9007199254740992.0);
}

static inline double power_heuristic(double a, double b) {
  double a2 = a * a, b2 = b * b;
  return a2 + b2 > 0.0 ? a2 / (a2 + b2) : 0.0;
}
static inline double lambert_pdf(double cos) { return cos > 0.0 ? cos * (1.0 / M_PI) : 0.0; }

/* --- one work unit's buffers: two ray wavefronts (read one, write the next), shadow segments, estimates ---- */
typedef struct { double *o, *d, *beta, *pdf; int32_t *path; } Rays;
typedef struct { float *o, *d, *tfar; int32_t *path; double *c; } Shadows;
typedef struct {
  Rays a, b; /* the wavefront read, the one written */
  Shadows sh;
  int32_t *prim; /* closest hits */
  char *visible; /* shadow segments unoccluded */
  double *L, *sum, *sum2; /* estimates of the unit's paths; this thread's film */
  double query_cpu;       /* seconds in Embree's queries, with CLOCK_QUERIES */
  long long rays;
} Work;

static double now(clockid_t clock) {
  struct timespec t;
  clock_gettime(clock, &t);
  return t.tv_sec + 1e-9 * t.tv_nsec;
}

/* The toolkit's closest_triangles: rays 0 .. n-1 in 8-wide packets, tnear 0, tfar 1e37, primitive or -1. */
static void closest(RTCScene scene, const Rays *r, int n, int32_t *prim, const struct RTCIntersectArguments *args) {
  struct RTCRayHit8 rh;
  int valid[8] __attribute__((aligned(32)));
  memset(&rh, 0, sizeof rh);
  for (int first = 0; first < n; first += 8) {
    int m = n - first < 8 ? n - first : 8;
    for (int k = 0; k < 8; k++) {
      valid[k] = k < m ? -1 : 0;
      rh.tfar[k] = 1e37f, rh.geomID[k] = RTC_INVALID_GEOMETRY_ID, rh.mask[k] = 0xFFFFFFFFu;
      if (k >= m) continue;
      const double *o = r->o + 3 * (first + k), *d = r->d + 3 * (first + k);
      rh.org_x[k] = (float)o[0], rh.org_y[k] = (float)o[1], rh.org_z[k] = (float)o[2];
      rh.dir_x[k] = (float)d[0], rh.dir_y[k] = (float)d[1], rh.dir_z[k] = (float)d[2];
    }
    rtcIntersect8(valid, scene, &rh, args);
    for (int k = 0; k < m; k++) prim[first + k] = rh.geomID[k] == RTC_INVALID_GEOMETRY_ID ? -1 : (int32_t)rh.primID[k];
  }
}

/* The toolkit's segments_clear: visible[k] unless a triangle lies on segment k (Embree sets tfar to -inf). */
static void unoccluded(RTCScene scene, const Shadows *s, int n, char *visible) {
  struct RTCRayHit8 rh;
  int valid[8] __attribute__((aligned(32)));
  memset(&rh, 0, sizeof rh);
  for (int first = 0; first < n; first += 8) {
    int m = n - first < 8 ? n - first : 8;
    for (int k = 0; k < 8; k++) {
      valid[k] = k < m ? -1 : 0;
      rh.mask[k] = 0xFFFFFFFFu;
      if (k >= m) continue;
      const float *o = s->o + 3 * (first + k), *d = s->d + 3 * (first + k);
      rh.org_x[k] = o[0], rh.org_y[k] = o[1], rh.org_z[k] = o[2], rh.tfar[k] = s->tfar[first + k];
      rh.dir_x[k] = d[0], rh.dir_y[k] = d[1], rh.dir_z[k] = d[2];
    }
    rtcOccluded8(valid, scene, &rh, NULL);
    for (int k = 0; k < m; k++) visible[first + k] = !(rh.tfar[k] < 0.0f);
  }
}

static inline void set_ray(Rays *r, int i, V o, V d, int32_t path, V beta, double pdf) {
  double *po = r->o + 3 * i, *pd = r->d + 3 * i, *pb = r->beta + 3 * i;
  po[0] = o.x, po[1] = o.y, po[2] = o.z, pd[0] = d.x, pd[1] = d.y, pd[2] = d.z;
  pb[0] = beta.x, pb[1] = beta.y, pb[2] = beta.z, r->pdf[i] = pdf, r->path[i] = path;
}

/* One bounce of pathtracer._shade for Lambertian triangles: the emission each hit finds (MIS-weighted against
   light sampling), one NEE shadow segment (an emitter triangle by power, a point on it by area, power
   heuristic), one cosine-sampled continuation ray with Russian roulette. Each line keeps the toolkit's
   order of operations (core/direct.py, lights.py, bsdf.py, sampling.py, roulette.py), so that the float64
   results are the same to the bit. Returns the shadow segments written; *nn: the continuation rays. */
static int shade(const Scene *s, const Rays *cur, Rays *nxt, Shadows *sh, const int32_t *prim, int n, double *L,
                 uint64_t key, int64_t first, int depth, int extend, int roulette, int *nn) {
  const int32_t *h = s->h;
  const double eps = s->offset;
  int ns = 0, nr = 0;
  for (int i = 0; i < n; i++) {
    int p = prim[i];
    if (p < 0) continue;
    V d = v3(cur->d, i), o = v3(cur->o, i), nrm = v3(s->normal, p), v0 = v3(s->v0, p);
    double cos_o = -dot(d, nrm);
    double t = ((v0.x - o.x) * nrm.x + (v0.y - o.y) * nrm.y + (v0.z - o.z) * nrm.z) / -cos_o;
    t = t < 0.0 ? 0.0 : t;
    V x = mad(o, t, d);
    if (!(cos_o > 0.0)) continue; /* back side: one-sided emitters and BSDFs give nothing, the path ends */
    int32_t q = cur->path[i];
    V beta = v3(cur->beta, i), rho = v3(s->rho, p);
    double *Lq = L + 3 * q, pa = s->pdf_area[p];
    if (pa > 0.0 && cos_o > 0.0) { /* emission: MIS weight 1 for a camera ray (pdf 0) */
      double pdf = cur->pdf[i], w = pdf == 0.0 ? 1.0 : power_heuristic(pdf, pa * t * t / cos_o);
      V le = v3(s->radiance, p);
      Lq[0] += beta.x * le.x * w, Lq[1] += beta.y * le.y * w, Lq[2] += beta.z * le.z * w;
    }
    if (!extend) continue;
    uint64_t path = (uint64_t)(first + q), dim = (uint64_t)(h[DIM_VERTEX] + (depth - 1) * h[VERTEX_STRIDE]);
    if (h[NE] > 0) { /* next-event estimation: core/direct.py light_sample with MIS */
      double u0 = uniform(key, path, dim + h[OFF_PICK]);
      double u1 = uniform(key, path, dim + h[OFF_LIGHT]), u2 = uniform(key, path, dim + h[OFF_LIGHT] + 1);
      int lo = 0, hi = h[NE]; /* searchsorted(cdf, u0, side="right") */
      while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (s->cdf[mid] <= u0) lo = mid + 1;
        else hi = mid;
      }
      int64_t e = s->emitters[lo < h[NE] - 1 ? lo : h[NE] - 1];
      double su = sqrt(u1), b1 = su * (1.0 - u2), b2 = su * u2;
      V y = mad(mad(v3(s->v0, e), b1, v3(s->e1, e)), b2, v3(s->e2, e)), ny = v3(s->normal, e);
      double pe = s->pdf_area[e];
      V w = {y.x - x.x, y.y - x.y, y.z - x.z};
      double dist2 = dot(w, w), cos_x = 0.0, cos_y = 0.0;
      if (dist2 > 0.0) {
        double dist = sqrt(dist2);
        V wi = {w.x / dist, w.y / dist, w.z / dist};
        cos_x = dot(nrm, wi), cos_y = -dot(ny, wi);
        if (!(cos_x > 0.0 && cos_y > 0.0)) cos_x = 0.0;
      }
      if (cos_x > 0.0 && pe > 0.0) {
        double mis = power_heuristic(cos_y > 0.0 ? pe * dist2 / cos_y : 0.0, lambert_pdf(cos_x));
        double g = cos_x * cos_y / dist2 * mis / pe;
        V a = mad(x, eps, nrm), b = mad(y, eps, ny);
        V sd = {b.x - a.x, b.y - a.y, b.z - a.z};
        double sl = sqrt(dot(sd, sd));
        if (sl > 0.0) {
          V le = v3(s->radiance, e);
          float *so = sh->o + 3 * ns, *sdir = sh->d + 3 * ns;
          double *c = sh->c + 3 * ns;
          so[0] = (float)a.x, so[1] = (float)a.y, so[2] = (float)a.z;
          sdir[0] = (float)(sd.x / sl), sdir[1] = (float)(sd.y / sl), sdir[2] = (float)(sd.z / sl);
          sh->tfar[ns] = (float)(sl * s->shadow_tfar_rel), sh->path[ns] = q;
          c[0] = beta.x * rho.x * (1.0 / M_PI) * le.x * g;
          c[1] = beta.y * rho.y * (1.0 / M_PI) * le.y * g;
          c[2] = beta.z * rho.z * (1.0 / M_PI) * le.z * g;
          ns++;
        }
      }
    }
    /* BSDF sample: a cosine-weighted direction (Malley; Duff et al.'s basis), weight rho */
    double u1 = uniform(key, path, dim + h[OFF_BSDF]), u2 = uniform(key, path, dim + h[OFF_BSDF] + 1);
    double r = sqrt(u1), phi = 2.0 * M_PI * u2, lx = r * cos(phi), ly = r * sin(phi);
    double lz = sqrt(1.0 - u1 > 0.0 ? 1.0 - u1 : 0.0);
    double sign = nrm.z >= 0.0 ? 1.0 : -1.0, ka = -1.0 / (sign + nrm.z), kb = nrm.x * nrm.y * ka;
    V bs = {1.0 + sign * nrm.x * nrm.x * ka, sign * kb, -sign * nrm.x}, bt = {kb, sign + nrm.y * nrm.y * ka, -nrm.y};
    V wi = {bs.x * lx + bt.x * ly + nrm.x * lz, bs.y * lx + bt.y * ly + nrm.y * lz, bs.z * lx + bt.z * ly + nrm.z * lz};
    if (!(lz > 0.0)) continue;
    /* core/roulette.py continue_path (no refraction in a Lambertian scene: its scale is 1) */
    V b = {beta.x * rho.x, beta.y * rho.y, beta.z * rho.z};
    double bmax = b.x > b.y ? (b.x > b.z ? b.x : b.z) : (b.y > b.z ? b.y : b.z);
    if (bmax <= 0.0) continue;
    if (roulette) {
      double survive = bmax < s->q_max ? bmax : s->q_max;
      if (!(uniform(key, path, dim + h[OFF_ROULETTE]) < survive)) continue;
      b = (V){b.x / survive, b.y / survive, b.z / survive};
    }
    set_ray(nxt, nr++, mad(x, eps, nrm), wi, q, b, lambert_pdf(lz));
  }
  *nn = nr;
  return ns;
}

/* pathtracer._trace for paths first .. first+m-1 of a pass: their estimates into w->L; the rays traced. */
static long long trace_unit(const Scene *s, Work *w, uint64_t key, int64_t first, int m, int clock_queries) {
  const int32_t *h = s->h;
  const double *bs = s->basis;
  int64_t pixels = (int64_t)h[WIDTH] * h[HEIGHT];
  Rays *cur = &w->a, *nxt = &w->b, *tmp;
  memset(w->L, 0, sizeof(double) * 3 * m);
  for (int i = 0; i < m; i++) { /* core/camera.py camera_rays: pixel (first + i) mod P, jittered */
    int64_t j = first + i, pixel = j % pixels, row = pixel / h[WIDTH], col = pixel % h[WIDTH];
    double u = uniform(key, (uint64_t)j, h[DIM_CAMERA]), v = uniform(key, (uint64_t)j, h[DIM_CAMERA] + 1);
    double sx = 2.0 * ((double)col + u) / h[WIDTH] - 1.0, sy = 1.0 - 2.0 * ((double)row + v) / h[HEIGHT];
    V d = {bs[9] + sx * bs[3] + sy * bs[6], bs[10] + sx * bs[4] + sy * bs[7], bs[11] + sx * bs[5] + sy * bs[8]};
    double inv = 1.0 / sqrt(dot(d, d));
    set_ray(cur, i, (V){bs[0], bs[1], bs[2]}, (V){d.x * inv, d.y * inv, d.z * inv}, i, (V){1.0, 1.0, 1.0}, 0.0);
  }
  long long traced = 0;
  for (int n = m, depth = 1, nn; n; depth++, n = nn) {
    double c0 = clock_queries ? now(CLOCK_THREAD_CPUTIME_ID) : 0.0;
    closest(s->scene, cur, n, w->prim, depth == 1 ? s->camera_args : NULL);
    double c1 = clock_queries ? now(CLOCK_THREAD_CPUTIME_ID) : 0.0;
    int extend = h[MAX_DEPTH] < 0 || depth + 1 <= h[MAX_DEPTH];
    int ns = shade(s, cur, nxt, &w->sh, w->prim, n, w->L, key, first, depth, extend, depth >= h[RR_DEPTH], &nn);
    double c2 = clock_queries ? now(CLOCK_THREAD_CPUTIME_ID) : 0.0;
    unoccluded(s->scene, &w->sh, ns, w->visible);
    if (clock_queries) w->query_cpu += (c1 - c0) + (now(CLOCK_THREAD_CPUTIME_ID) - c2);
    for (int k = 0; k < ns; k++) /* rays.add_unoccluded, in segment order */
      if (w->visible[k])
        for (int c = 0; c < 3; c++) w->L[3 * w->sh.path[k] + c] += w->sh.c[3 * k + c];
    traced += n + ns;
    tmp = cur, cur = nxt, nxt = tmp;
  }
  return traced;
}

static void die(const char *what, const char *name) {
  fprintf(stderr, "pathtracer_c: %s%s\n", what, name);
  exit(2);
}

static void *alloc(size_t bytes) {
  void *p = aligned_alloc(64, (bytes + 63) / 64 * 64 + 64);
  if (p == NULL) die("out of memory", "");
  return p;
}

static void work_buffers(Work *w, int m) {
  size_t n = (size_t)m;
  memset(w, 0, sizeof *w);
  Rays *rs[2] = {&w->a, &w->b};
  for (int k = 0; k < 2; k++)
    *rs[k] = (Rays){alloc(24 * n), alloc(24 * n), alloc(24 * n), alloc(8 * n), alloc(4 * n)};
  w->sh = (Shadows){alloc(12 * n), alloc(12 * n), alloc(4 * n), alloc(4 * n), alloc(24 * n)};
  w->prim = alloc(4 * n), w->visible = alloc(n), w->L = alloc(24 * n);
}

/* --- the render: schedule.py's passes and work units, units taken from one counter ------------------------ */
typedef struct { int pass; int64_t first; int m; } Unit;
typedef struct {
  const Scene *s;
  const Unit *units;
  int n_units, clock_queries, *next;
  Work w;
} Thread;

static void *worker(void *arg) {
  Thread *t = arg;
  int64_t pixels = (int64_t)t->s->h[WIDTH] * t->s->h[HEIGHT];
  for (int u; (u = __atomic_fetch_add(t->next, 1, __ATOMIC_RELAXED)) < t->n_units;) {
    const Unit *un = t->units + u;
    t->w.rays += trace_unit(t->s, &t->w, t->s->keys[un->pass], un->first, un->m, t->clock_queries);
    for (int i = 0; i < un->m; i++) { /* core/film.py accumulate: pixel (first + i) mod P */
      int64_t k = (un->first + i) % pixels;
      for (int c = 0; c < 3; c++) {
        double v = t->w.L[3 * i + c];
        t->w.sum[3 * k + c] += v, t->w.sum2[3 * k + c] += v * v;
      }
    }
  }
  return NULL;
}

static int render(const Scene *s, int threads, int clock_queries, const char *out_path) {
  const int32_t *h = s->h;
  int64_t pixels = (int64_t)h[WIDTH] * h[HEIGHT], paths = 0;
  int n_units = 0, unit_max = 0;
  Unit *units = NULL;
  for (int k = 0; k < h[PASSES]; k++) { /* schedule.unit_size: enough units for the threads, within bounds */
    int64_t total = s->pass_paths[k], size = (total + 2 * threads - 1) / (2 * threads);
    size = size < h[MIN_UNIT] ? h[MIN_UNIT] : size > h[MAX_UNIT] ? h[MAX_UNIT] : size;
    for (int64_t first = 0; first < total; first += size) {
      units = realloc(units, sizeof(Unit) * (n_units + 1));
      int m = (int)(total - first < size ? total - first : size);
      units[n_units++] = (Unit){k, first, m};
      unit_max = m > unit_max ? m : unit_max;
    }
    paths += total;
  }
  Thread *ts = calloc(threads, sizeof(Thread));
  pthread_t *ids = calloc(threads, sizeof(pthread_t));
  int next = 0;
  for (int k = 0; k < threads; k++) {
    ts[k] = (Thread){s, units, n_units, clock_queries, &next};
    work_buffers(&ts[k].w, unit_max);
    ts[k].w.sum = calloc(3 * pixels, sizeof(double)), ts[k].w.sum2 = calloc(3 * pixels, sizeof(double));
  }
  double t0 = now(CLOCK_MONOTONIC), c0 = now(CLOCK_PROCESS_CPUTIME_ID);
  for (int k = 0; k < threads; k++) pthread_create(&ids[k], NULL, worker, &ts[k]);
  for (int k = 0; k < threads; k++) pthread_join(ids[k], NULL);
  double wall = now(CLOCK_MONOTONIC) - t0, cpu = now(CLOCK_PROCESS_CPUTIME_ID) - c0, query = 0.0;
  long long rays = 0;
  for (int k = 0; k < threads; k++) {
    rays += ts[k].w.rays, query += ts[k].w.query_cpu;
    for (int64_t i = 0; k > 0 && i < 3 * pixels; i++)
      ts[0].w.sum[i] += ts[k].w.sum[i], ts[0].w.sum2[i] += ts[k].w.sum2[i];
  }
  printf("%d %lld %lld %.6f %.6f %.6f\n", threads, (long long)paths, rays, wall, cpu, query);
  FILE *f = fopen(out_path, "wb");
  if (f == NULL || fwrite(ts[0].w.sum, 8, 3 * pixels, f) != (size_t)(3 * pixels) ||
      fwrite(ts[0].w.sum2, 8, 3 * pixels, f) != (size_t)(3 * pixels) || fclose(f) != 0)
    die("cannot write ", out_path);
  return 0;
}

static void *read_array(FILE *f, size_t count, size_t size) {
  void *p = alloc(count * size);
  if (fread(p, size, count, f) != count) die("the scene file ends early", "");
  return p;
}

/* The scene file, in the driver's order (pathtracer_c.py write_scene). */
static void load(Scene *s, const char *path, int mitsuba) {
  FILE *f = fopen(path, "rb");
  if (f == NULL) die("cannot open ", path);
  int32_t *h = read_array(f, HEADER_INTS, 4);
  double *d = read_array(f, 15, 8);
  memcpy(s->h, h, sizeof s->h);
  s->offset = d[0], s->q_max = d[1], s->shadow_tfar_rel = d[2];
  memcpy(s->basis, d + 3, sizeof s->basis);
  float *vertices = read_array(f, 3 * (size_t)h[NV], 4);
  uint32_t *triangles = read_array(f, 3 * (size_t)h[NT], 4);
  double **tables[6] = {&s->v0, &s->e1, &s->e2, &s->normal, &s->rho, &s->radiance};
  for (int k = 0; k < 6; k++) *tables[k] = read_array(f, 3 * (size_t)h[NT], 8);
  s->pdf_area = read_array(f, h[NT], 8);
  s->emitters = read_array(f, h[NE], 8), s->cdf = read_array(f, h[NE], 8);
  s->keys = read_array(f, h[PASSES], 8), s->pass_paths = read_array(f, h[PASSES], 8);
  fclose(f);
  RTCDevice device = rtcNewDevice(NULL);
  s->scene = rtcNewScene(device);
  static const struct RTCIntersectArguments coherent = {RTC_RAY_QUERY_FLAG_COHERENT, -1, NULL, NULL, NULL, 0.0f};
  s->camera_args = mitsuba ? &coherent : NULL;
  rtcSetSceneFlags(s->scene, mitsuba ? 0 : RTC_SCENE_FLAG_ROBUST); /* toolkit: core/embree.py's scene */
  if (mitsuba) rtcSetSceneBuildQuality(s->scene, RTC_BUILD_QUALITY_HIGH); /* Mitsuba's scene_embree.inl */
  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  memcpy(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, h[NV]), vertices, 12 * h[NV]);
  memcpy(rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, h[NT]), triangles, 12 * h[NT]);
  rtcCommitGeometry(geom);
  rtcAttachGeometry(s->scene, geom);
  rtcReleaseGeometry(geom);
  rtcCommitScene(s->scene);
  printf("embree %zd\n", rtcGetDeviceProperty(device, 0));
}

int main(int argc, char **argv) {
  Scene s;
  int mitsuba = argc > 2 && strcmp(argv[2], "mitsuba") == 0;
  if (argc < 4 || (!mitsuba && strcmp(argv[2], "toolkit") != 0)) argc = 0; /* to the usage */
  if (argc == 7 && strcmp(argv[3], "render") == 0 && atoi(argv[4]) >= 1 && atoi(argv[4]) <= 64) {
    load(&s, argv[1], mitsuba);
    return render(&s, atoi(argv[4]), atoi(argv[5]), argv[6]);
  }
  if (argc == 8 && strcmp(argv[3], "paths") == 0) {
    load(&s, argv[1], mitsuba);
    int pass = atoi(argv[4]);
    int64_t first = atoll(argv[5]), m = atoll(argv[6]) - first;
    if (pass < 0 || pass >= s.h[PASSES] || first < 0 || m < 1 || first + m > s.pass_paths[pass])
      die("no such paths in pass ", argv[4]);
    Work w;
    work_buffers(&w, (int)m);
    printf("rays %lld\n", trace_unit(&s, &w, s.keys[pass], first, (int)m, 0));
    FILE *f = fopen(argv[7], "wb");
    return f == NULL || fwrite(w.L, 8, 3 * m, f) != (size_t)(3 * m) || fclose(f) != 0;
  }
  fprintf(stderr, "usage: pathtracer_c SCENE toolkit|mitsuba render THREADS(1-64) CLOCK_QUERIES SUMS_OUT\n"
                  "       pathtracer_c SCENE toolkit|mitsuba paths PASS FIRST STOP ESTIMATES_OUT\n");
  return 2;
}
