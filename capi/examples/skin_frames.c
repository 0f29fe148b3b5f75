/*
 * Skinning from C through the Skinfield C ABI, as an engine would: load a .skf, map the
 * engine's skeleton onto it by joint name, bind a mesh, then per frame pose it from the
 * engine's local transforms (in the engine's order) and skin it into an interleaved vertex
 * buffer, by the exact path (SkinNet at every vertex) and by the fast path (SkinNet at 128
 * nodes, the other vertices interpolated). The inputs and the Rust runtime's answers come from
 * the `fixture` example; the program exits 0 when every position and normal of both paths
 * agrees with Rust to 1e-6 and the last frame's top-k influences are well formed.
 *
 *   skin_frames MODEL.skf FIXTURE_DIR
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "skinfield.h"

#define TOLERANCE 1e-6f

/* The engine's vertex: position, a UV the skinning leaves alone, normal, padding. */
typedef struct Vertex {
  float position[3];
  float uv[2];
  float normal[3];
} Vertex;

static void *read_file(const char *dir, const char *name, size_t *len) {
  char path[4096];
  snprintf(path, sizeof path, "%s/%s", dir, name);
  FILE *f = fopen(path, "rb");
  if (!f) {
    fprintf(stderr, "cannot open %s\n", path);
    exit(2);
  }
  fseek(f, 0, SEEK_END);
  long size = ftell(f);
  fseek(f, 0, SEEK_SET);
  void *data = malloc(size > 0 ? (size_t)size : 1);
  if (!data || fread(data, 1, (size_t)size, f) != (size_t)size) {
    fprintf(stderr, "cannot read %s\n", path);
    exit(2);
  }
  fclose(f);
  *len = (size_t)size;
  return data;
}

static void check(SkfStatus status, const char *what) {
  if (status != SKF_STATUS_OK) {
    fprintf(stderr, "%s failed (status %d): %s\n", what, (int)status, skf_last_error());
    exit(1);
  }
}

int main(int argc, char **argv) {
  if (argc != 3) {
    fprintf(stderr, "usage: %s MODEL.skf FIXTURE_DIR\n", argv[0]);
    return 2;
  }
  const char *dir = argv[2];

  /* Load time. */
  SkfModel *model = NULL;
  check(skf_model_load_file(argv[1], &model), "skf_model_load_file");

  size_t engine_len;
  char *engine = read_file(dir, "engine.txt", &engine_len);
  size_t joints = 0;
  for (size_t i = 0; i < engine_len; i++) joints += engine[i] == '\n';
  const char **names = malloc(joints * sizeof *names);
  int32_t *parents = malloc(joints * sizeof *parents);
  char *line = engine;
  for (size_t j = 0; j < joints; j++) {
    char *tab = strchr(line, '\t');
    char *end = strchr(line, '\n');
    *tab = '\0';
    *end = '\0';
    parents[j] = (int32_t)atoi(line);
    names[j] = tab + 1;
    line = end + 1;
  }
  check(skf_model_map_joints(model, names, joints, parents), "skf_model_map_joints");

  size_t mesh_len;
  unsigned char *mesh_bytes = read_file(dir, "mesh.bin", &mesh_len);
  uint64_t vertices;
  memcpy(&vertices, mesh_bytes, 8);
  const float *positions = (const float *)(mesh_bytes + 8);
  const float *normals = positions + 3 * vertices;
  SkfMesh *mesh = NULL;
  check(skf_mesh_bind(model, positions, normals, NULL, (size_t)vertices, &mesh), "skf_mesh_bind");

  SkfFrame *frame = NULL;
  SkfScratch *scratch = NULL;
  check(skf_frame_new(model, &frame), "skf_frame_new");
  check(skf_scratch_new(model, &scratch), "skf_scratch_new");
  SkfVertexLayout layout = {
      .stride = sizeof(Vertex),
      .position_offset = offsetof(Vertex, position),
      .normal_offset = offsetof(Vertex, normal),
      .tangent_offset = SKF_ABSENT,
  };
  size_t buffer_len = skf_vertex_buffer_len(&layout, (size_t)vertices);
  Vertex *vbo = calloc((size_t)vertices, sizeof(Vertex));
  if (buffer_len == 0 || buffer_len > vertices * sizeof(Vertex)) {
    fprintf(stderr, "unexpected buffer length %zu\n", buffer_len);
    return 1;
  }

  /* Per frame. */
  size_t frames_len, reference_len;
  unsigned char *frames = read_file(dir, "frames.bin", &frames_len);
  const float *reference = read_file(dir, "reference.bin", &reference_len);
  uint64_t frame_count, frame_joints;
  memcpy(&frame_count, frames, 8);
  memcpy(&frame_joints, frames + 8, 8);
  if (frame_joints != joints) {
    fprintf(stderr, "frames.bin has %llu joints, engine.txt %zu\n",
            (unsigned long long)frame_joints, joints);
    return 1;
  }
  const SkfTransform *locals = (const SkfTransform *)(frames + 16);
  float worst = 0.0f;
  for (uint64_t f = 0; f < frame_count; f++) {
    for (size_t v = 0; v < vertices; v++) vbo[v].uv[0] = vbo[v].uv[1] = 42.0f;
    check(skf_frame_set_pose(frame, model, locals + f * joints, joints), "skf_frame_set_pose");
    uint32_t method = f % 2 == 0 ? SKF_METHOD_LBS : SKF_METHOD_DQS;
    check(skf_skin(model, mesh, frame, scratch, method, 0, (size_t)vertices, &layout,
                   (uint8_t *)vbo, buffer_len),
          "skf_skin");
    const float *want = reference + f * vertices * 6;
    for (size_t v = 0; v < vertices; v++) {
      for (int k = 0; k < 3; k++) {
        float dp = fabsf(vbo[v].position[k] - want[6 * v + k]);
        float dn = fabsf(vbo[v].normal[k] - want[6 * v + 3 + k]);
        worst = fmaxf(worst, fmaxf(dp, dn));
      }
      if (vbo[v].uv[0] != 42.0f || vbo[v].uv[1] != 42.0f) {
        fprintf(stderr, "frame %llu: vertex %zu's UV was overwritten\n", (unsigned long long)f, v);
        return 1;
      }
    }
  }

  /* The fast path: bound once over the mesh's triangles, SkinNet at the nodes once per frame,
   * then any vertex ranges. */
  size_t triangles_len, reference_fast_len;
  unsigned char *triangle_bytes = read_file(dir, "triangles.bin", &triangles_len);
  const float *reference_fast = read_file(dir, "reference_fast.bin", &reference_fast_len);
  uint64_t triangle_count;
  memcpy(&triangle_count, triangle_bytes, 8);
  if (triangles_len != 8 + 12 * triangle_count) {
    fprintf(stderr, "triangles.bin: %zu bytes for %llu triangles\n", triangles_len,
            (unsigned long long)triangle_count);
    return 1;
  }
  const uint32_t *triangles = (const uint32_t *)(triangle_bytes + 8);
  SkfFastOptions options = skf_fast_options_default();
  SkfFastMesh *fast_mesh = NULL;
  SkfFastNodes *nodes = NULL;
  size_t node_count = 0;
  check(skf_fast_mesh_bind(model, mesh, triangles, (size_t)triangle_count, &options, &fast_mesh),
        "skf_fast_mesh_bind");
  check(skf_fast_nodes_new(fast_mesh, &nodes), "skf_fast_nodes_new");
  check(skf_fast_mesh_node_count(fast_mesh, &node_count), "skf_fast_mesh_node_count");
  float worst_fast = 0.0f, fast_from_exact = 0.0f;
  for (uint64_t f = 0; f < frame_count; f++) {
    check(skf_frame_set_pose(frame, model, locals + f * joints, joints), "skf_frame_set_pose");
    uint32_t method = f % 2 == 0 ? SKF_METHOD_LBS : SKF_METHOD_DQS;
    check(skf_fast_nodes_update(model, fast_mesh, frame, scratch, nodes),
          "skf_fast_nodes_update");
    check(skf_skin_fast(fast_mesh, frame, nodes, method, 4, 0, (size_t)vertices, &layout,
                        (uint8_t *)vbo, buffer_len),
          "skf_skin_fast");
    const float *want = reference_fast + f * vertices * 6;
    const float *exact = reference + f * vertices * 6;
    for (size_t v = 0; v < vertices; v++) {
      for (int k = 0; k < 3; k++) {
        float dp = fabsf(vbo[v].position[k] - want[6 * v + k]);
        float dn = fabsf(vbo[v].normal[k] - want[6 * v + 3 + k]);
        worst_fast = fmaxf(worst_fast, fmaxf(dp, dn));
        fast_from_exact = fmaxf(fast_from_exact, fabsf(vbo[v].position[k] - exact[6 * v + k]));
      }
    }
  }

  /* The last frame as each vertex's 4 strongest joints (engine order) and unorm8 weights, for
   * an engine that skins on its own: every vertex's weights sum to exactly 255. */
  uint8_t *top_joints = malloc(4 * (size_t)vertices), *top_weights = malloc(4 * (size_t)vertices);
  if (!top_joints || !top_weights) {
    fprintf(stderr, "out of memory\n");
    return 1;
  }
  check(skf_fast_top_k(model, fast_mesh, frame, nodes, 4, 0, (size_t)vertices,
                       SKF_TOP_K_INDEX_U8, top_joints, 4 * (size_t)vertices,
                       SKF_TOP_K_WEIGHT_UNORM8, top_weights, 4 * (size_t)vertices),
        "skf_fast_top_k");
  size_t top_k_bad = 0;
  for (size_t v = 0; v < vertices; v++) {
    unsigned sum = 0;
    for (int k = 0; k < 4; k++) {
      sum += top_weights[4 * v + k];
      top_k_bad += top_joints[4 * v + k] >= joints;
    }
    top_k_bad += sum != 255;
  }
  free(top_joints);
  free(top_weights);

  /* A bad argument is a status and a message, not a crash. */
  SkfStatus bad = skf_skin(model, mesh, frame, scratch, 7, 0, (size_t)vertices, &layout,
                           (uint8_t *)vbo, buffer_len);
  printf("C ABI: %zu engine joints, %llu vertices, %llu frames: worst |C - Rust| = %.3g "
         "(tolerance %.0e); bad method -> status %d: %s\n",
         joints, (unsigned long long)vertices, (unsigned long long)frame_count, worst,
         TOLERANCE, (int)bad, skf_last_error());
  printf("C ABI fast path: %zu nodes, %llu triangles: worst |C - Rust| = %.3g (tolerance %.0e); "
         "largest position difference from the exact path %.3g (model units)\n",
         node_count, (unsigned long long)triangle_count, worst_fast, TOLERANCE, fast_from_exact);
  printf("C ABI top-k: 4 joints per vertex (u8, unorm8), %zu vertices with a weight sum other "
         "than 255 or a joint outside the engine's %zu\n",
         top_k_bad, joints);

  skf_fast_nodes_free(nodes);
  skf_fast_mesh_free(fast_mesh);
  skf_scratch_free(scratch);
  skf_frame_free(frame);
  skf_mesh_free(mesh);
  skf_model_free(model);
  free(vbo);
  free(triangle_bytes);
  free((void *)reference_fast);
  free(frames);
  free((void *)reference);
  free(mesh_bytes);
  free(parents);
  free(names);
  free(engine);
  int agrees = worst <= TOLERANCE && worst_fast <= TOLERANCE && top_k_bad == 0;
  return agrees && bad == SKF_STATUS_INVALID_ARGUMENT ? 0 : 1;
}
