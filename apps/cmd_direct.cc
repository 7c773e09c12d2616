// ptmkit direct LIGHTS.lp --light x,y,z -o OUT.png: the photos themselves blended by the
// barycentric weights of the light in the Delaunay triangulation of the input lights.
#include <cstdio>
#include <memory>
#include <string>

#include "commands.h"
#include "flags.h"
#include "ptmkit/core/error.h"
#include "ptmkit/core/light_set.h"
#include "ptmkit/texture/direct.h"

namespace ptmkit::app {

namespace {
struct DirectArgs {
  std::string lights, light, output;
};
}  // namespace

void add_direct_command(CLI::App& root) {
  auto a = std::make_shared<DirectArgs>();
  CLI::App* cmd = root.add_subcommand(
      "direct",
      "Direct light-dependent rendering from the input photos (Delaunay triangulation "
      "of the light directions, barycentric blend of three photos; outside the hull "
      "the nearest hull point's blend).");
  cmd->add_option("lights", a->lights, "Light file (.lp) of the photos")->required();
  cmd->add_option("--light", a->light, "Direction toward the light, x,y,z (light frame)")
      ->required();
  cmd->add_option("-o,--output", a->output, "Output image (written atomically)")->required();
  cmd->callback([a] {
    const Eigen::Vector3d v = parse_vector3(a->light, "--light");
    const LightSet set = read_lp(a->lights);
    const texture::DirectReport r = texture::direct_from_light_set(set, v, a->output);
    const auto& w = r.weights;
    std::printf(
        "direct: %d photos, %d triangles; light %s: photos %d %d %d weights %.3f %.3f "
        "%.3f%s; wrote %s\n",
        r.photos, r.triangles, w.inside ? "inside" : "outside the hull (nearest point)",
        w.index[0] + 1, w.index[1] + 1, w.index[2] + 1, w.weight[0], w.weight[1], w.weight[2], "",
        a->output.c_str());
  });
}

}  // namespace ptmkit::app
