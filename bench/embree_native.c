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

/* A committed scene of one triangle mesh, with Embree's default flags and build quality
 * (as embreex makes it); NULL on failure. */
Native *native_scene(const float *vertices, size_t vertex_count, const uint32_t *triangles,
                     size_t triangle_count) {
  Native *native = calloc(1, sizeof(Native));
  if (!native || !(native->device = rtcNewDevice(NULL))) {
    free(native);
    return NULL;
  }
  native->scene = rtcNewScene(native->device);
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

static void trace_range(Pass *p, size_t begin, size_t end) {
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
