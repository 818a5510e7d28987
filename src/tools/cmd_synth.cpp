// umvs synth: a synthetic MVSNet-format scene with exact ground truth (core/synth.h).
#include <torch/torch.h>

#include <chrono>
#include <iostream>

#include "unsup_mvs/core/device.h"
#include "unsup_mvs/core/synth.h"
#include "unsup_mvs/io/synth_writer.h"
#include "unsup_mvs/io/texture_bank.h"
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"

UMVS_COMMAND(synth, "render a synthetic scene with exact ground truth (depth, gt.ply)") {
  umvs::Args args("synth",
                  "Ray-casts a textured synthetic scene and writes an MVSNet-format folder with ground truth:\n"
                  "  OUT/images/XXXXXXXX.png, OUT/cams/XXXXXXXX_cam.txt, OUT/pair.txt,\n"
                  "  OUT/depth_gt/XXXXXXXX.pfm (z-depth, 0 = nothing hit) + .png preview, OUT/masks/XXXXXXXX.png,\n"
                  "  OUT/gt.ply (surface points seen by some view), OUT/scene.txt (settings).\n"
                  "Scenes: dtu_like (objects on a table, ~0.4-1 m), room (indoor robot path, 0.5-8 m),\n"
                  "facade (street walk, 2-40 m), corridor (a robot driving down an office corridor, 0.3-30 m).\n"
                  "Surfaces wear photographs from --textures (scripts/install_textures.sh installs the default\n"
                  "collections; docs/synthetic.md) or procedural textures. The same settings and texture files\n"
                  "always give identical files.");
  args.required("out", "output folder")
      .option("scene", "room", "dtu_like | room | facade | corridor")
      .option("seed", "1", "layout, textures, lights and random trajectories")
      .option("path-seed", "",
              "another pass through the same scene: new viewpoints between and beside the first pass's "
              "(default: none)")
      .option("views", "10", "number of views")
      .option("width", "320", "image width in pixels")
      .option("height", "256", "image height in pixels")
      .option("trajectory", "default",
              "default | orbit | forward | random | drive | turn (default: orbit for dtu_like, drive for corridor, "
              "forward otherwise)")
      .option("lighting-change", "1", "1 = per-view gain/bias and a moving light, 0 = constant lighting")
      .flag("specular", "add specular highlights (only with --lighting-change 1)")
      .option("texture", "1.0", "texture contrast: 0 = textureless surfaces, 1 = default, up to 2")
      .option("textures", "installed",
              "photographic textures: folders DIR[,DIR] (searched recursively), 'installed' = the collections "
              "scripts/install_textures.sh installs when present (procedural otherwise), 'none' = procedural only")
      .option("photo-fraction", "0.75", "share of the textured surfaces that wear a photograph")
      .option("texture-size", "512", "photographs are shrunk to at most this many pixels on their longest side")
      .option("supersample", "2", "anti-aliasing rays per pixel along each axis")
      .option("gt-samples", "300000", "area samples for gt.ply before visibility culling (0 = no gt.ply)")
      .option("threads", 0, "CPU threads (0 = all cores)");
  if (!args.parse(argc, argv)) return 0;
  umvs::configure_threads(args.integer("threads"));

  umvs::SynthConfig cfg;
  cfg.scene = umvs::synth_scene_from_string(args.str("scene"));
  const long long seed = std::stoll(args.str("seed"));
  if (seed < 0) throw std::invalid_argument("--seed must not be negative");
  cfg.seed = static_cast<uint64_t>(seed);
  if (args.given("path-seed")) {
    const std::string text = args.str("path-seed");
    if (text.empty() || text.size() > 18 || text.find_first_not_of("0123456789") != std::string::npos) {
      throw std::invalid_argument("--path-seed must be a non-negative integer, got '" + text + "'");
    }
    cfg.path_seed = std::stoull(text);
  }
  cfg.num_views = args.integer("views");
  cfg.width = args.integer("width");
  cfg.height = args.integer("height");
  cfg.trajectory = umvs::synth_trajectory_from_string(args.str("trajectory"));
  const int lighting = args.integer("lighting-change");
  if (lighting != 0 && lighting != 1) throw std::invalid_argument("--lighting-change must be 0 or 1");
  cfg.lighting_change = lighting == 1;
  cfg.specular = args.on("specular");
  cfg.texture_strength = args.real("texture");
  cfg.supersample = args.integer("supersample");
  cfg.gt_cloud_samples = args.integer("gt-samples");
  cfg.photo_texture_fraction = args.real("photo-fraction");

  std::vector<std::string> texture_folders;
  const std::string textures = args.str("textures");
  if (textures == "installed") {
    texture_folders = umvs::installed_texture_folders();
    if (texture_folders.empty()) {
      std::cout << "no photographic texture collection installed (scripts/install_textures.sh installs them): "
                   "using procedural textures\n";
    }
  } else if (textures != "none") {
    texture_folders = args.all("textures");
  }
  if (!texture_folders.empty()) {
    const umvs::TextureBank bank = umvs::load_texture_bank(texture_folders, args.integer("texture-size"));
    cfg.photo_textures = bank.images;
    std::cout << "photographic textures: " << bank.images.size() << " images from";
    for (const auto& f : texture_folders) std::cout << " " << f;
    std::cout << "\n";
    for (const auto& s : bank.skipped) std::cout << "  skipped " << s << "\n";
  }

  const auto t0 = std::chrono::steady_clock::now();
  const umvs::SynthScene scene = umvs::render_synthetic_scene(cfg);
  const double render_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const std::string out = args.str("out");
  umvs::write_synthetic_scene(out, scene, cfg, texture_folders);
  std::cout << "rendered " << scene.views.size() << " views of '" << umvs::to_string(cfg.scene) << "' (seed " << cfg.seed
            << ", " << cfg.width << "x" << cfg.height << ") in " << render_s << " s on " << torch::get_num_threads()
            << " threads\n"
            << "depth range " << scene.depth_min << " .. " << scene.depth_max << ", gt.ply " << scene.gt_cloud.size()
            << " points (spacing ~" << scene.gt_cloud_spacing << ")\n"
            << "wrote " << out << "/{images,cams,depth_gt,masks}/, pair.txt" << (scene.gt_cloud.empty() ? "" : ", gt.ply")
            << ", scene.txt\n";
  return 0;
}
