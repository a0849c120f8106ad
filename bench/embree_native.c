/* Embree 4 called per ray from C, for bench/embree_compare.py: the Embree figure without
 * embreex's Python-level loop (tens of ns per ray), which otherwise has to be estimated and
 * taken off. The script compiles this file against the libembree4 that embreex ships and
 * calls it through ctypes, on the same numpy arrays it gives canopy.
 *
 * Only the handful of Embree 4 declarations used here are repeated below (the wheel ships
 * no headers). The hit record is declared with room to spare: Embree builds that store
 * instance-array ids write a few bytes past the basic record.
 */
#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef struct RTCDeviceTy *RTCDevice;
typedef struct RTCSceneTy *RTCScene;
typedef struct RTCGeometryTy *RTCGeometry;

enum { RTC_GEOMETRY_TYPE_TRIANGLE = 0 };
enum { RTC_BUFFER_TYPE_INDEX = 0, RTC_BUFFER_TYPE_VERTEX = 1 };
enum { RTC_FORMAT_UINT3 = 0x5003, RTC_FORMAT_FLOAT3 = 0x9003 };
enum { RTC_SCENE_FLAG_ROBUST = 1 << 2 };
#define RTC_INVALID_GEOMETRY_ID ((unsigned)-1)

struct __attribute__((aligned(16))) RTCRay {
  float org_x, org_y, org_z, tnear;
  float dir_x, dir_y, dir_z, time;
  float tfar;
  unsigned mask, id, flags;
};

struct __attribute__((aligned(16))) RTCHit {
  float Ng_x, Ng_y, Ng_z, u, v;
  unsigned primID, geomID;
  unsigned instance_ids[9]; /* instID[], and instPrimID[] where built in */
};

struct RTCRayHit {
  struct RTCRay ray;
  struct RTCHit hit;
};

RTCDevice rtcNewDevice(const char *config);
void rtcReleaseDevice(RTCDevice device);
int rtcGetDeviceError(RTCDevice device);
RTCScene rtcNewScene(RTCDevice device);
void rtcReleaseScene(RTCScene scene);
void rtcCommitScene(RTCScene scene);
void rtcSetSceneFlags(RTCScene scene, int flags);
RTCGeometry rtcNewGeometry(RTCDevice device, int type);
void *rtcSetNewGeometryBuffer(RTCGeometry geometry, int type, unsigned slot, int format,
                              size_t byte_stride, size_t item_count);
void rtcCommitGeometry(RTCGeometry geometry);
unsigned rtcAttachGeometry(RTCScene scene, RTCGeometry geometry);
void rtcReleaseGeometry(RTCGeometry geometry);
void rtcIntersect1(RTCScene scene, struct RTCRayHit *rayhit, void *args);
void rtcOccluded1(RTCScene scene, struct RTCRay *ray, void *args);

typedef struct {
  RTCDevice device;
  RTCScene scene;
} Native;

void native_release(Native *native);

/* A committed scene of one triangle mesh, with Embree's default build quality, and its
 * default flags (as embreex makes it) or, when `robust`, RTC_SCENE_FLAG_ROBUST: Embree's
 * watertight mode, the counterpart of canopy's default triangle test. NULL on failure. */
Native *native_scene(const float *vertices, size_t vertex_count, const uint32_t *triangles,
                     size_t triangle_count, int robust) {
  Native *native = calloc(1, sizeof(Native));
  if (!native || !(native->device = rtcNewDevice(NULL))) {
    free(native);
    return NULL;
  }
  native->scene = rtcNewScene(native->device);
  if (robust)
    rtcSetSceneFlags(native->scene, RTC_SCENE_FLAG_ROBUST);
  RTCGeometry mesh = rtcNewGeometry(native->device, RTC_GEOMETRY_TYPE_TRIANGLE);
  float *v = rtcSetNewGeometryBuffer(mesh, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                     3 * sizeof(float), vertex_count);
  uint32_t *t = rtcSetNewGeometryBuffer(mesh, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                        3 * sizeof(uint32_t), triangle_count);
  if (v && t) {
    memcpy(v, vertices, 3 * sizeof(float) * vertex_count);
    memcpy(t, triangles, 3 * sizeof(uint32_t) * triangle_count);
    rtcCommitGeometry(mesh);
    rtcAttachGeometry(native->scene, mesh);
  }
  rtcReleaseGeometry(mesh);
  rtcCommitScene(native->scene);
  if (!v || !t || rtcGetDeviceError(native->device) != 0) {
    native_release(native);
    return NULL;
  }
  return native;
}

void native_release(Native *native) {
  rtcReleaseScene(native->scene);
  rtcReleaseDevice(native->device);
  free(native);
}

/* One pass over the rays. Workers take chunks of rays from a shared counter, as canopy's
 * batch calls do. Outputs: closest: distance (inf on a miss) and primitive (-1);
 * occlusion: 1 when blocked. */
typedef struct {
  RTCScene scene;
  const float *org, *dir;
  size_t count;
  int closest;
  float *t;
  int32_t *prim;
  uint8_t *blocked;
  atomic_size_t next;
} Pass;

enum { CHUNK = 4096 };

/* Out of line, so that a profiler can count the tracing alone (bench/kernel_profile.py:
 * `valgrind --tool=callgrind --toggle-collect=trace_range`). */
__attribute__((noinline)) static void trace_range(Pass *p, size_t begin, size_t end) {
  for (size_t i = begin; i < end; i++) {
    struct RTCRayHit rh;
    rh.ray.org_x = p->org[3 * i];
    rh.ray.org_y = p->org[3 * i + 1];
    rh.ray.org_z = p->org[3 * i + 2];
    rh.ray.tnear = 0.0f;
    rh.ray.dir_x = p->dir[3 * i];
    rh.ray.dir_y = p->dir[3 * i + 1];
    rh.ray.dir_z = p->dir[3 * i + 2];
    rh.ray.time = 0.0f;
    rh.ray.tfar = __builtin_inff();
    rh.ray.mask = (unsigned)-1;
    rh.ray.id = 0;
    rh.ray.flags = 0;
    if (p->closest) {
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      rtcIntersect1(p->scene, &rh, NULL);
      int hit = rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
      p->t[i] = hit ? rh.ray.tfar : __builtin_inff();
      p->prim[i] = hit ? (int32_t)rh.hit.primID : -1;
    } else {
      rtcOccluded1(p->scene, &rh.ray, NULL);
      /* Embree marks a blocked ray by setting tfar to -inf. */
      p->blocked[i] = rh.ray.tfar < 0.0f;
    }
  }
}

static void *worker(void *arg) {
  Pass *p = arg;
  for (;;) {
    size_t begin = atomic_fetch_add(&p->next, CHUNK);
    if (begin >= p->count)
      return NULL;
    size_t end = begin + CHUNK < p->count ? begin + CHUNK : p->count;
    trace_range(p, begin, end);
  }
}

/* Traces `count` rays (origins and directions as count x 3 floats) on `threads` threads,
 * the calling thread one of them. Returns 0, or -1 when a thread could not start. */
int native_trace(Native *native, const float *org, const float *dir, size_t count, int closest,
                 int threads, float *t, int32_t *prim, uint8_t *blocked) {
  Pass pass = {native->scene, org, dir, count, closest, t, prim, blocked, 0};
  pthread_t pool[64];
  int started = 0;
  if (threads < 1)
    threads = 1;
  if (threads > 64)
    threads = 64;
  for (; started < threads - 1; started++)
    if (pthread_create(&pool[started], NULL, worker, &pass) != 0)
      break;
  worker(&pass);
  for (int k = 0; k < started; k++)
    pthread_join(pool[k], NULL);
  return started == threads - 1 ? 0 : -1;
}

#ifdef NATIVE_PROFILE_MAIN
/* A program for bench/kernel_profile.py: `embree_profile MESH RAYS QUERY ROBUST RUNS` reads
 * the mesh (u64 vertex and triangle counts, float xyz, u32 triangles) and the rays (u64
 * count, float origins, float directions) the script wrote, traces them on one thread
 * RUNS times and prints the best pass's nanoseconds per ray (under a profiler, RUNS is 1
 * and only trace_range is counted). */
#include <stdio.h>
#include <time.h>

static void *read_all(const char *path, size_t *size) {
  FILE *f = fopen(path, "rb");
  if (!f)
    return NULL;
  fseek(f, 0, SEEK_END);
  long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  void *data = n > 0 ? malloc((size_t)n) : NULL;
  if (data && fread(data, 1, (size_t)n, f) != (size_t)n) {
    free(data);
    data = NULL;
  }
  fclose(f);
  *size = (size_t)n;
  return data;
}

int main(int argc, char **argv) {
  if (argc != 6) {
    fprintf(stderr, "usage: %s MESH RAYS closest|occluded ROBUST RUNS\n", argv[0]);
    return 2;
  }
  size_t mesh_size, ray_size;
  uint64_t *mesh = read_all(argv[1], &mesh_size), *rays = read_all(argv[2], &ray_size);
  if (!mesh || !rays) {
    fprintf(stderr, "cannot read %s or %s\n", argv[1], argv[2]);
    return 1;
  }
  size_t nv = mesh[0], nf = mesh[1], n = rays[0];
  const float *vertices = (const float *)(mesh + 2);
  const uint32_t *triangles = (const uint32_t *)(vertices + 3 * nv);
  const float *org = (const float *)(rays + 1), *dir = org + 3 * n;
  Native *native = native_scene(vertices, nv, triangles, nf, atoi(argv[4]));
  if (!native) {
    fprintf(stderr, "Embree could not build the scene\n");
    return 1;
  }
  float *t = malloc(n * sizeof(float));
  int32_t *prim = malloc(n * sizeof(int32_t));
  uint8_t *blocked = malloc(n);
  int closest = strcmp(argv[3], "closest") == 0, runs = atoi(argv[5]);
  double best = 1e300;
  for (int run = 0; run < (runs > 0 ? runs : 1); run++) {
    struct timespec a, b;
    clock_gettime(CLOCK_MONOTONIC, &a);
    native_trace(native, org, dir, n, closest, 1, t, prim, blocked);
    clock_gettime(CLOCK_MONOTONIC, &b);
    double ns = (b.tv_sec - a.tv_sec) * 1e9 + (b.tv_nsec - a.tv_nsec);
    best = ns < best ? ns : best;
  }
  size_t answered = 0;
  for (size_t i = 0; i < n; i++)
    answered += closest ? prim[i] >= 0 : blocked[i];
  printf("ns_per_ray %.3f hits %zu\n", best / n, answered);
  native_release(native);
  return 0;
}
#endif
