/* ao: ambient occlusion of a cornell-harness scene, read from its neutral JSON export, written as PFM.
 *
 *   cbox export --scene cornell-box-ao --format json --out d     (d/scene.json)
 *   ./ao d/scene.json out.pfm 64 0                               (scene, image, spp, seed)
 *
 * What it computes is the scene's own definition (src/cornell_harness/schemas/json-scene.schema.json,
 * "ambient_occlusion"): at the first surface a camera ray hits, with n the geometric normal turned to the
 * camera, the fraction of cosine-weighted (or uniform) hemisphere directions that meet nothing nearer than
 * max_distance; miss_value where the camera ray hits nothing. One direction per sample, so each sample is
 * 0 or 1 and the pixel is their mean over jittered positions in its square (the box filter).
 * Brute force: every ray against every triangle, in double precision. No spheres (it says so and exits 2).
 * The JSON reader is purpose-built: a recursive descent over the file that hands each number and string
 * to scene_number()/scene_string() with its key path ("camera.basis.right", "meshes.vertices").
 */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const double PI = 3.14159265358979323846;

/* ---------------------------------------------------------------- the scene */

static double position[3], right[3], up[3], forward[3], vfov_deg;
static int width, height, version, spheres;
static char format[64], quantity[64], weighting[64] = "cosine";
static double ao_distance = INFINITY, miss_value; /* max_distance null: no limit */
static double *verts, *tris;   /* tris: per triangle v0, e1 = v1 - v0, e2 = v2 - v0 (9 doubles) */
static long *indices;
static long nverts, nindices, cap_verts, cap_indices, mesh_base, ntris;

static void die(const char *what, const char *detail) {
    fprintf(stderr, "ao: %s%s\n", what, detail);
    exit(2);
}

static void *grow(void *data, long *cap, long need, size_t size) {
    if (need <= *cap) return data;
    *cap = need * 2;
    data = realloc(data, (size_t)*cap * size);
    if (!data) die("out of memory", "");
    return data;
}

static void scene_number(const char *path, int nth, double v) {
    double *vec = !strcmp(path, "camera.position") ? position : !strcmp(path, "camera.basis.right") ? right
                : !strcmp(path, "camera.basis.up") ? up : !strcmp(path, "camera.basis.forward") ? forward : NULL;
    if (vec && nth < 3) vec[nth] = v;
    else if (!strcmp(path, "camera.vertical_fov_deg")) vfov_deg = v;
    else if (!strcmp(path, "camera.width")) width = (int)v;
    else if (!strcmp(path, "camera.height")) height = (int)v;
    else if (!strcmp(path, "version")) version = (int)v;
    else if (!strcmp(path, "ambient_occlusion.max_distance")) ao_distance = v;
    else if (!strcmp(path, "ambient_occlusion.miss_value")) miss_value = v;
    else if (!strcmp(path, "spheres.radius")) spheres++;
    else if (!strcmp(path, "meshes.vertices")) {
        verts = grow(verts, &cap_verts, nverts + 1, sizeof *verts);
        verts[nverts++] = v;
    } else if (!strcmp(path, "meshes.triangles")) { /* indices are the mesh's own: offset to the shared array */
        indices = grow(indices, &cap_indices, nindices + 1, sizeof *indices);
        indices[nindices++] = mesh_base + (long)v;
    }
}

static void scene_string(const char *path, const char *s) {
    if (!strcmp(path, "format")) snprintf(format, sizeof format, "%s", s);
    else if (!strcmp(path, "quantity")) snprintf(quantity, sizeof quantity, "%s", s);
    else if (!strcmp(path, "ambient_occlusion.weighting")) snprintf(weighting, sizeof weighting, "%s", s);
}

static void scene_object(const char *path) {
    if (!strcmp(path, "meshes")) mesh_base = nverts / 3; /* a mesh begins */
}

/* ---------------------------------------------------------------- the JSON reader */

static const char *json, *at;
static int nth; /* how many numbers the current key has had (its array's flat index) */

static void bad_json(const char *what) {
    char where[48];
    snprintf(where, sizeof where, " at byte %ld of the scene file", (long)(at - json));
    die(what, where);
}

static void space(void) { while (*at == ' ' || *at == '\n' || *at == '\r' || *at == '\t') at++; }

static void string(char *out, size_t size) { /* escapes are kept as the character after the backslash */
    size_t n = 0;
    if (*at++ != '"') bad_json("expected a string");
    for (; *at != '"'; at++) {
        if (!*at) bad_json("unterminated string");
        if (*at == '\\' && !*++at) bad_json("unterminated string");
        if (n + 1 < size) out[n++] = *at;
    }
    at++;
    out[n] = 0;
}

static void value(char *path, size_t len) {
    char text[64];
    space();
    if (*at == '{') {
        scene_object(path);
        at++, space();
        while (*at != '}') {
            string(text, sizeof text);
            space();
            if (*at++ != ':') bad_json("expected ':'");
            snprintf(path + len, 256 - len, "%s%s", len ? "." : "", text);
            nth = 0;
            value(path, strlen(path));
            path[len] = 0;
            space();
            if (*at == ',') at++, space();
            else if (*at != '}') bad_json("expected ',' or '}'");
        }
        at++;
    } else if (*at == '[') {
        at++, space();
        while (*at != ']') {
            value(path, len);
            space();
            if (*at == ',') at++;
            else if (*at != ']') bad_json("expected ',' or ']'");
        }
        at++;
    } else if (*at == '"') {
        string(text, sizeof text);
        scene_string(path, text);
    } else if (!strncmp(at, "null", 4) || !strncmp(at, "true", 4)) {
        at += 4;
    } else if (!strncmp(at, "false", 5)) {
        at += 5;
    } else {
        char *end;
        double v = strtod(at, &end);
        if (end == at) bad_json("unexpected character");
        at = end;
        scene_number(path, nth++, v);
    }
}

static void read_scene(const char *file) {
    FILE *f = fopen(file, "rb");
    if (!f) die("cannot open ", file);
    fseek(f, 0, SEEK_END);
    long size = ftell(f);
    rewind(f);
    char *text = malloc((size_t)size + 1), path[256] = "";
    if (!text || fread(text, 1, (size_t)size, f) != (size_t)size) die("cannot read ", file);
    fclose(f);
    text[size] = 0;
    json = at = text;
    value(path, 0);
    free(text);
    if (strcmp(format, "cornell-harness-scene") || version != 1) die("not a version 1 cornell-harness scene: ", file);
    if (strcmp(quantity, "ambient_occlusion")) die("the scene's quantity is not ambient_occlusion but ", quantity);
    if (spheres) die("analytic spheres are not supported", "");
    if (strcmp(weighting, "cosine") && strcmp(weighting, "uniform")) die("unknown weighting ", weighting);
    ntris = nindices / 3;
    tris = malloc(sizeof *tris * 9 * (size_t)(ntris ? ntris : 1));
    for (long t = 0; t < ntris; t++)
        for (int k = 0; k < 3; k++) {
            long i0 = indices[3 * t], i1 = indices[3 * t + 1], i2 = indices[3 * t + 2];
            if (i0 * 3 >= nverts || i1 * 3 >= nverts || i2 * 3 >= nverts) die("a triangle index is out of range", "");
            tris[9 * t + k] = verts[3 * i0 + k];
            tris[9 * t + 3 + k] = verts[3 * i1 + k] - verts[3 * i0 + k];
            tris[9 * t + 6 + k] = verts[3 * i2 + k] - verts[3 * i0 + k];
        }
}

/* ---------------------------------------------------------------- rays */

static double dot(const double *a, const double *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

static void cross(const double *a, const double *b, double *out) {
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

/* The nearest triangle the ray o + t d meets with 0 < t < tmax (Moller-Trumbore), or -1; its t in *hit_t. */
static long intersect(const double *o, const double *d, double tmax, double *hit_t) {
    long hit = -1;
    for (long i = 0; i < ntris; i++) {
        const double *v0 = tris + 9 * i, *e1 = v0 + 3, *e2 = v0 + 6;
        double p[3], q[3], s[3] = {o[0] - v0[0], o[1] - v0[1], o[2] - v0[2]};
        cross(d, e2, p);
        double det = dot(e1, p);
        if (det == 0.0) continue;
        double u = dot(s, p) / det;
        if (u < 0.0 || u > 1.0) continue;
        cross(s, e1, q);
        double v = dot(d, q) / det;
        if (v < 0.0 || u + v > 1.0) continue;
        double t = dot(e2, q) / det;
        if (t > 0.0 && t < tmax) tmax = t, hit = i, *hit_t = t;
    }
    return hit;
}

static uint64_t rng_state;
static double uniform01(void) { /* splitmix64, 53 bits */
    uint64_t z = (rng_state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return (double)((z ^ (z >> 31)) >> 11) * 0x1.0p-53;
}

/* One sample of the pixel at continuous image point (x, y): 0 or 1, or miss_value. */
static double sample(double x, double y, double tx, double ty, double offset) {
    double sx = (2.0 * x / width - 1.0) * tx, sy = (1.0 - 2.0 * y / height) * ty, d[3], t, n[3], o[3], w[3];
    for (int k = 0; k < 3; k++) d[k] = forward[k] + sx * right[k] + sy * up[k];
    long tri = intersect(position, d, INFINITY, &t);
    if (tri < 0) return miss_value;
    cross(tris + 9 * tri + 3, tris + 9 * tri + 6, n);
    double len = sqrt(dot(n, n)), side = dot(n, d) > 0.0 ? -1.0 : 1.0; /* the side the camera sees */
    for (int k = 0; k < 3; k++) n[k] *= side / len;
    /* An orthonormal frame (b1, b2, n) (Duff et al. 2017), then a direction in the hemisphere about n. */
    double sign = copysign(1.0, n[2]), a = -1.0 / (sign + n[2]), b = n[0] * n[1] * a;
    double b1[3] = {1.0 + sign * n[0] * n[0] * a, sign * b, -sign * n[0]}, b2[3] = {b, sign + n[1] * n[1] * a, -n[1]};
    double u1 = uniform01(), phi = 2.0 * PI * uniform01();
    double cos_theta = strcmp(weighting, "cosine") ? u1 : sqrt(1.0 - u1); /* uniform: cos θ = u1 */
    double sin_theta = sqrt(fmax(0.0, 1.0 - cos_theta * cos_theta));
    for (int k = 0; k < 3; k++) {
        w[k] = sin_theta * cos(phi) * b1[k] + sin_theta * sin(phi) * b2[k] + cos_theta * n[k];
        o[k] = position[k] + t * d[k] + offset * n[k];
    }
    double reach = ao_distance;
    return intersect(o, w, reach, &t) < 0 ? 1.0 : 0.0;
}

int main(int argc, char **argv) {
    if (argc != 5) die("usage: ao SCENE.json OUT.pfm SPP SEED", "");
    read_scene(argv[1]);
    long spp = atol(argv[3]);
    uint64_t seed = strtoull(argv[4], NULL, 10);
    if (spp < 1 || width < 1 || height < 1) die("spp and the resolution must be positive", "");
    double ty = tan(vfov_deg * PI / 360.0), tx = ty * width / height, lo = INFINITY, hi = -INFINITY;
    for (long i = 0; i < nverts; i++) lo = fmin(lo, verts[i]), hi = fmax(hi, verts[i]);
    double offset = 1e-9 * fmax(1.0, hi - lo); /* leaves the surface, well inside double precision */
    float *image = malloc(sizeof *image * 3 * (size_t)width * (size_t)height);
    for (int row = 0; row < height; row++)
        for (int col = 0; col < width; col++) {
            uint64_t pixel = (uint64_t)row * (uint64_t)width + (uint64_t)col;
            rng_state = seed * 0x100000001B3ull ^ pixel * 0xD1B54A32D192ED03ull; /* a stream per pixel and seed */
            double sum = 0.0;
            for (long s = 0; s < spp; s++) {
                double jx = uniform01(), jy = uniform01();
                sum += sample(col + jx, row + jy, tx, ty, offset);
            }
            for (int k = 0; k < 3; k++) image[3 * ((size_t)row * width + col) + k] = (float)(sum / spp);
        }
    /* PFM: "PF", the size, the scale (negative: little-endian floats), then rows from the BOTTOM up. */
    FILE *f = fopen(argv[2], "wb");
    if (!f) die("cannot write ", argv[2]);
    const uint16_t one = 1;
    fprintf(f, "PF\n%d %d\n%s\n", width, height, *(const uint8_t *)&one ? "-1.0" : "1.0");
    for (int row = height - 1; row >= 0; row--)
        fwrite(image + 3 * (size_t)row * width, sizeof *image, 3 * (size_t)width, f);
    if (fclose(f)) die("cannot write ", argv[2]);
    return 0;
}
