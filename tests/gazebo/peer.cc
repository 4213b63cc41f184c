// A scripted Gazebo robot on the real gz-transport (Debian 12: libignition-transport11,
// libignition-msgs8), for tests/gazebo.rs and scripts/gazebo_bench.sh. It publishes what
// gz-sim's systems publish, with their topic names, message types and rates:
//   DiffDrive:  subscribes /model/NAME/cmd_vel (Twist), integrates it, publishes
//               /model/NAME/odometry (Odometry) at 50 Hz
//   gpu_lidar:  LaserScan on --lidar TOPIC at 10 Hz: 360 rays over 360 degrees, ray-cast
//               in a fixed room (walls at x, y = +-5 m, a 1 m box at (2.5, -2.5))
//   camera:     Image (RGB_INT8) on --camera TOPIC, --width x --height at --fps
//   --pantilt:  JointPositionController on pan_joint and tilt_joint (subscribes
//               /model/NAME/joint/JOINT/0/cmd_pos, Double; moves at most 2 rad/s) and
//               JointStatePublisher (/world/room/model/NAME/joint_state, Model, 50 Hz)
//   imu:        IMU on --imu TOPIC at 100 Hz: the true heading as a quaternion, the turn
//               rate (rad/s) and the specific force (m/s^2, +9.80665 up at rest), as the
//               Imu system reports them
// Header stamps are the simulation time (seconds since start), or the wall clock with
// --wallstamp (for latency benchmarks).
//
//   peer robot --model NAME [--lidar T] [--camera T] [--width W --height H --fps F]
//        [--wallstamp] [--lidar-hz H] [--imu T]
//   peer sub --topic T --type laser|image --seconds S   (a C++ subscriber for benchmarks:
//        prints one JSON line: count, rate, p50 latency (wall stamps))
//   peer echo-twist --topic T --seconds S   (prints each Twist as "twist LX AZ")
//   peer decode-bench [--rays N]   (C++ protobuf's parse of a LaserScan: median ns)
#include <ignition/msgs/double.pb.h>
#include <ignition/msgs/image.pb.h>
#include <ignition/msgs/imu.pb.h>
#include <ignition/msgs/model.pb.h>
#include <ignition/msgs/laserscan.pb.h>
#include <ignition/msgs/odometry.pb.h>
#include <ignition/msgs/twist.pb.h>
#include <ignition/transport/Node.hh>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

using namespace std::chrono;
namespace msgs = ignition::msgs;

static std::atomic<bool> running{true};
static void on_signal(int) { running = false; }

static std::map<std::string, std::string> args(int argc, char **argv) {
  std::map<std::string, std::string> a;
  for (int i = 2; i < argc; ++i) {
    std::string k = argv[i];
    if (k.rfind("--", 0) == 0) {
      if (i + 1 < argc && std::string(argv[i + 1]).rfind("--", 0) != 0)
        a[k.substr(2)] = argv[++i];
      else
        a[k.substr(2)] = "1";
    }
  }
  return a;
}

static double wall() {
  return duration<double>(system_clock::now().time_since_epoch()).count();
}

static void stamp(msgs::Header *h, double t) {
  h->mutable_stamp()->set_sec(static_cast<int64_t>(std::floor(t)));
  h->mutable_stamp()->set_nsec(static_cast<int32_t>((t - std::floor(t)) * 1e9));
}

// Distance from (x, y) along angle a to the room's walls or the box.
static double cast(double x, double y, double a, double maxr) {
  double dx = std::cos(a), dy = std::sin(a), best = maxr;
  auto hit = [&](double t) { if (t > 1e-9 && t < best) best = t; };
  // Walls at x = +-5, y = +-5.
  if (std::fabs(dx) > 1e-12) { hit((5 - x) / dx); hit((-5 - x) / dx); }
  if (std::fabs(dy) > 1e-12) { hit((5 - y) / dy); hit((-5 - y) / dy); }
  // A box [2, 3] x [-3, -2]: slab test.
  double t0 = 0, t1 = maxr;
  double lo[2] = {2, -3}, hi[2] = {3, -2}, o[2] = {x, y}, d[2] = {dx, dy};
  bool miss = false;
  for (int k = 0; k < 2; ++k) {
    if (std::fabs(d[k]) < 1e-12) {
      if (o[k] < lo[k] || o[k] > hi[k]) miss = true;
    } else {
      double ta = (lo[k] - o[k]) / d[k], tb = (hi[k] - o[k]) / d[k];
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
    }
  }
  if (!miss && t0 <= t1) hit(t0);
  return best;
}

static int robot(std::map<std::string, std::string> a) {
  std::string model = a.count("model") ? a["model"] : "robot1";
  bool wallstamp = a.count("wallstamp") > 0;
  ignition::transport::Node node;
  std::mutex mu;
  double v = 0, w = 0, x = 0, y = 0, yaw = 0;
  auto t0 = steady_clock::now();
  auto simtime = [&]() {
    return wallstamp ? wall() : duration<double>(steady_clock::now() - t0).count();
  };
  std::function<void(const msgs::Twist &)> cb = [&](const msgs::Twist &m) {
    std::lock_guard<std::mutex> l(mu);
    v = m.linear().x();
    w = m.angular().z();
  };
  std::string cmd = "/model/" + model + "/cmd_vel";
  if (!node.Subscribe(cmd, cb)) { std::fprintf(stderr, "cannot subscribe %s\n", cmd.c_str()); return 1; }
  auto odom = node.Advertise<msgs::Odometry>("/model/" + model + "/odometry");
  std::vector<std::thread> threads;
  // DiffDrive: 50 Hz.
  threads.emplace_back([&]() {
    auto next = steady_clock::now();
    msgs::Odometry m;
    while (running) {
      next += milliseconds(20);
      std::this_thread::sleep_until(next);
      {
        std::lock_guard<std::mutex> l(mu);
        double dt = 0.02;
        x += v * std::cos(yaw) * dt;
        y += v * std::sin(yaw) * dt;
        yaw += w * dt;
        stamp(m.mutable_header(), simtime());
        m.mutable_pose()->mutable_position()->set_x(x);
        m.mutable_pose()->mutable_position()->set_y(y);
        m.mutable_pose()->mutable_orientation()->set_z(std::sin(yaw / 2));
        m.mutable_pose()->mutable_orientation()->set_w(std::cos(yaw / 2));
        m.mutable_twist()->mutable_linear()->set_x(v);
        m.mutable_twist()->mutable_angular()->set_z(w);
      }
      odom.Publish(m);
    }
  });
  if (a.count("lidar")) {
    double hz = a.count("lidar-hz") ? std::stod(a["lidar-hz"]) : 10.0;
    threads.emplace_back([&, hz]() {
      auto pub = node.Advertise<msgs::LaserScan>(a["lidar"]);
      auto next = steady_clock::now();
      msgs::LaserScan m;
      const int n = 360;
      while (running) {
        next += microseconds(static_cast<int64_t>(1e6 / hz));
        std::this_thread::sleep_until(next);
        double px, py, pyaw;
        { std::lock_guard<std::mutex> l(mu); px = x; py = y; pyaw = yaw; }
        m.set_frame(model + "::lidar_link::lidar");
        m.set_angle_min(-M_PI);
        m.set_angle_max(M_PI - 2 * M_PI / n);
        m.set_angle_step(2 * M_PI / n);
        m.set_range_min(0.08);
        m.set_range_max(10.0);
        m.set_count(n);
        m.set_vertical_count(1);
        m.clear_ranges();
        m.clear_intensities();
        for (int k = 0; k < n; ++k) {
          double r = cast(px, py, pyaw - M_PI + k * 2 * M_PI / n, 10.0);
          m.add_ranges(r >= 10.0 ? INFINITY : r);
          m.add_intensities(0);
        }
        stamp(m.mutable_header(), simtime());
        pub.Publish(m);
      }
    });
  }
  if (a.count("imu")) {
    threads.emplace_back([&]() {
      auto pub = node.Advertise<msgs::IMU>(a["imu"]);
      auto next = steady_clock::now();
      msgs::IMU m;
      double last_v = 0;
      while (running) {
        next += milliseconds(10);
        std::this_thread::sleep_until(next);
        {
          std::lock_guard<std::mutex> l(mu);
          m.set_entity_name(model + "::base_link::imu");
          m.mutable_orientation()->set_x(0);
          m.mutable_orientation()->set_y(0);
          m.mutable_orientation()->set_z(std::sin(yaw / 2));
          m.mutable_orientation()->set_w(std::cos(yaw / 2));
          m.mutable_angular_velocity()->set_z(w);
          m.mutable_linear_acceleration()->set_x((v - last_v) / 0.01);
          m.mutable_linear_acceleration()->set_y(v * w);
          m.mutable_linear_acceleration()->set_z(9.80665);
          last_v = v;
          stamp(m.mutable_header(), simtime());
        }
        pub.Publish(m);
      }
    });
  }
  if (a.count("camera")) {
    int W = a.count("width") ? std::stoi(a["width"]) : 320;
    int H = a.count("height") ? std::stoi(a["height"]) : 240;
    double fps = a.count("fps") ? std::stod(a["fps"]) : 30.0;
    threads.emplace_back([&, W, H, fps]() {
      auto pub = node.Advertise<msgs::Image>(a["camera"]);
      auto next = steady_clock::now();
      msgs::Image m;
      std::string data(static_cast<size_t>(W) * H * 3, '\0');
      uint32_t k = 0;
      while (running) {
        next += microseconds(static_cast<int64_t>(1e6 / fps));
        std::this_thread::sleep_until(next);
        // A red left half, a blue right half, a frame counter in the first pixel's green.
        for (int r = 0; r < H; ++r)
          for (int c = 0; c < W; ++c) {
            size_t i = (static_cast<size_t>(r) * W + c) * 3;
            data[i] = c < W / 2 ? char(200) : 0;
            data[i + 1] = 0;
            data[i + 2] = c < W / 2 ? 0 : char(200);
          }
        data[1] = static_cast<char>(k++ & 0xff);
        m.set_width(W);
        m.set_height(H);
        m.set_step(W * 3);
        m.set_pixel_format_type(msgs::PixelFormatType::RGB_INT8);
        m.set_data(data);
        stamp(m.mutable_header(), simtime());
        pub.Publish(m);
      }
    });
  }
  double pan = 0, tilt = 0, pan_cmd = 0, tilt_cmd = 0;
  std::function<void(const msgs::Double &)> pan_cb = [&](const msgs::Double &m) {
    std::lock_guard<std::mutex> l(mu);
    pan_cmd = m.data();
  };
  std::function<void(const msgs::Double &)> tilt_cb = [&](const msgs::Double &m) {
    std::lock_guard<std::mutex> l(mu);
    tilt_cmd = m.data();
  };
  if (a.count("pantilt")) {
    node.Subscribe("/model/" + model + "/joint/pan_joint/0/cmd_pos", pan_cb);
    node.Subscribe("/model/" + model + "/joint/tilt_joint/0/cmd_pos", tilt_cb);
    threads.emplace_back([&]() {
      auto pub = node.Advertise<msgs::Model>("/world/room/model/" + model + "/joint_state");
      auto next = steady_clock::now();
      while (running) {
        next += milliseconds(20);
        std::this_thread::sleep_until(next);
        msgs::Model m;
        {
          std::lock_guard<std::mutex> l(mu);
          auto step = [](double &x, double to) {
            double d = std::max(-0.04, std::min(0.04, to - x));
            x += d;
          };
          step(pan, pan_cmd);
          step(tilt, tilt_cmd);
          m.set_name(model);
          auto *j = m.add_joint();
          j->set_name("pan_joint");
          j->mutable_axis1()->set_position(pan);
          j = m.add_joint();
          j->set_name("tilt_joint");
          j->mutable_axis1()->set_position(tilt);
          stamp(m.mutable_header(), simtime());
        }
        pub.Publish(m);
      }
    });
  }
  std::printf("peer ready: model %s\n", model.c_str());
  std::fflush(stdout);
  while (running) std::this_thread::sleep_for(milliseconds(50));
  for (auto &t : threads) t.join();
  return 0;
}

static double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

static int sub(std::map<std::string, std::string> a) {
  ignition::transport::Node node;
  std::mutex mu;
  std::vector<double> lat;
  std::atomic<int> count{0};
  double secs = a.count("seconds") ? std::stod(a["seconds"]) : 5;
  std::string type = a["type"];
  auto t_of = [](const msgs::Header &h) { return h.stamp().sec() + h.stamp().nsec() * 1e-9; };
  bool ok;
  std::function<void(const msgs::LaserScan &)> lcb = [&](const msgs::LaserScan &m) {
    double l = wall() - t_of(m.header());
    std::lock_guard<std::mutex> g(mu);
    lat.push_back(l);
    ++count;
  };
  std::function<void(const msgs::Image &)> icb = [&](const msgs::Image &m) {
    double l = wall() - t_of(m.header());
    std::lock_guard<std::mutex> g(mu);
    lat.push_back(l);
    ++count;
  };
  if (type == "laser") ok = node.Subscribe(a["topic"], lcb);
  else ok = node.Subscribe(a["topic"], icb);
  if (!ok) return 1;
  // Count from the first message on.
  while (running && count == 0) std::this_thread::sleep_for(milliseconds(5));
  int c0 = count;
  auto t0 = steady_clock::now();
  { std::lock_guard<std::mutex> g(mu); lat.clear(); }
  std::this_thread::sleep_for(duration<double>(secs));
  double el = duration<double>(steady_clock::now() - t0).count();
  std::lock_guard<std::mutex> g(mu);
  std::printf("{\"count\": %d, \"rate\": %.2f, \"p50_ms\": %.3f}\n", count - c0,
              (count - c0) / el, median(lat) * 1e3);
  return 0;
}

static int echo_twist(std::map<std::string, std::string> a) {
  ignition::transport::Node node;
  std::function<void(const msgs::Twist &)> cb = [](const msgs::Twist &m) {
    std::printf("twist %.4f %.4f\n", m.linear().x(), m.angular().z());
    std::fflush(stdout);
  };
  if (!node.Subscribe(a["topic"], cb)) return 1;
  double secs = a.count("seconds") ? std::stod(a["seconds"]) : 5;
  auto end = steady_clock::now() + duration<double>(secs);
  while (running && steady_clock::now() < end) std::this_thread::sleep_for(milliseconds(20));
  return 0;
}

// Parses a 360-ray LaserScan as gz-transport's subscriber does (ParseFromString),
// and reads its ranges: the median ns per message over 51 batches.
static int decode_bench(std::map<std::string, std::string> a) {
  int n = a.count("rays") ? std::stoi(a["rays"]) : 360;
  msgs::LaserScan m;
  stamp(m.mutable_header(), 12.5);
  m.set_frame("robot1::lidar_link::lidar");
  m.set_angle_min(-M_PI);
  m.set_angle_max(M_PI);
  m.set_angle_step(2 * M_PI / n);
  m.set_range_min(0.08);
  m.set_range_max(10);
  m.set_count(n);
  for (int k = 0; k < n; ++k) { m.add_ranges(1 + k * 0.001); m.add_intensities(0); }
  std::string wire;
  m.SerializeToString(&wire);
  std::vector<double> per;
  msgs::LaserScan out;
  volatile double sink = 0;
  const int batch = 2000;
  for (int b = 0; b < 51; ++b) {
    auto t0 = steady_clock::now();
    for (int i = 0; i < batch; ++i) {
      out.ParseFromString(wire);
      sink = sink + out.ranges(n / 2);
    }
    per.push_back(duration<double, std::nano>(steady_clock::now() - t0).count() / batch);
  }
  std::printf("{\"ns\": %.1f, \"bytes\": %zu}\n", median(per), wire.size());
  return 0;
}

int main(int argc, char **argv) {
  std::signal(SIGTERM, on_signal);
  std::signal(SIGINT, on_signal);
  if (argc < 2) { std::fprintf(stderr, "usage: peer robot|sub|echo-twist ...\n"); return 2; }
  std::string mode = argv[1];
  auto a = args(argc, argv);
  if (mode == "robot") return robot(a);
  if (mode == "sub") return sub(a);
  if (mode == "echo-twist") return echo_twist(a);
  if (mode == "decode-bench") return decode_bench(a);
  std::fprintf(stderr, "unknown mode %s\n", mode.c_str());
  return 2;
}
