/* The Cyclone DDS side of benches/ros2.rs: a ROS 2 node as rmw_cyclonedds would be
 * (topics rt/NAME, types of ros2_msgs.idl under ROS 2's DDS names, ROS 2's QoS),
 * in C on Debian's libddsc 0.10.2. Built by the bench with idlc and cc.
 *
 *   pub-image D SECS TOPIC     640x480 bgr8 Images, one per ms at most (sensor QoS)
 *   sub-image D SECS TOPIC     Images received per second -> {"rate": R, "n": N}
 *   pub-scan D SECS HZ         LaserScans stamped with the wall clock (sensor QoS);
 *                              ranges[0] = K/1000 m; prints "K NS" per scan
 *   sub-scan D SECS            latency now - stamp -> {"p50_ms": P, "n": N}
 *   pub-twist D SECS HZ        /cmd_vel (reliable): linear.x = K/1000 m/s, linear.y =
 *                              the wall time (s); prints "K NS" per Twist
 *   sub-twist D SECS           latency now - linear.y -> {"p50_ms": P, "n": N}
 *   pub-many D SECS HZ IMG     scan, odom (reliable) and, if IMG, Images at HZ
 *   sub-many D SECS IMG        reads rt/scan, rt/odom and, if IMG, rt/varcolorA/image_raw
 *                              -> {"scan": N, "odom": N, "image": N}
 * Publishers wait (10 s at most) for a matched reader before they start. */
#include <dds/dds.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "ros2_msgs.h"

#define W 640
#define H 480
#define MAXLAT 100000

static int64_t wall_ns(void) {
  struct timespec t;
  clock_gettime(CLOCK_REALTIME, &t);
  return (int64_t)t.tv_sec * 1000000000 + t.tv_nsec;
}

static double mono(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec + t.tv_nsec / 1e9;
}

static void stamp(std_msgs_msg_dds__Header_ *h, int64_t ns, char *frame) {
  h->stamp.sec = (int32_t)(ns / 1000000000);
  h->stamp.nanosec = (uint32_t)(ns % 1000000000);
  h->frame_id = frame;
}

static dds_qos_t *sensor_qos(void) {
  dds_qos_t *q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_BEST_EFFORT, 0);
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 5);
  return q;
}

static dds_qos_t *reliable_qos(void) {
  dds_qos_t *q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 10);
  return q;
}

static dds_entity_t endpoint(dds_entity_t dp, const dds_topic_descriptor_t *d,
                             const char *name, dds_qos_t *q, int writer) {
  dds_entity_t t = dds_create_topic(dp, d, name, NULL, NULL);
  if (t < 0) {
    fprintf(stderr, "topic %s: %s\n", name, dds_strretcode(-t));
    exit(2);
  }
  dds_entity_t e = writer ? dds_create_writer(dp, t, q, NULL) : dds_create_reader(dp, t, q, NULL);
  dds_delete_qos(q);
  if (e < 0) {
    fprintf(stderr, "endpoint %s: %s\n", name, dds_strretcode(-e));
    exit(2);
  }
  return e;
}

static void wait_matched(dds_entity_t w) {
  dds_publication_matched_status_t st;
  double end = mono() + 10;
  do {
    dds_get_publication_matched_status(w, &st);
    if (st.current_count > 0) return;
    dds_sleepfor(DDS_MSECS(10));
  } while (mono() < end);
  fprintf(stderr, "no reader matched in 10 s\n");
}

static int cmp(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return x < y ? -1 : x > y;
}

static void print_p50(double *lat, int n) {
  qsort(lat, n, sizeof *lat, cmp);
  printf("{\"p50_ms\": %.4f, \"n\": %d}\n", n ? lat[n / 2] : -1.0, n);
}

/* Takes every waiting sample of reader r (loaned); returns how many were valid
 * and calls f on each. */
typedef void (*on_sample)(const void *s);
static int take_all(dds_entity_t r, on_sample f) {
  void *buf[16] = {0};
  dds_sample_info_t info[16];
  int got = 0, n;
  while ((n = dds_take(r, buf, info, 16, 16)) > 0) {
    for (int i = 0; i < n; i++)
      if (info[i].valid_data) {
        got++;
        if (f) f(buf[i]);
      }
    dds_return_loan(r, buf, n);
  }
  return got;
}

static double *lat;
static int nlat;
static void scan_lat(const void *s) {
  const sensor_msgs_msg_dds__LaserScan_ *m = s;
  int64_t t = (int64_t)m->header.stamp.sec * 1000000000 + m->header.stamp.nanosec;
  if (nlat < MAXLAT) lat[nlat++] = (wall_ns() - t) / 1e6;
}
static void twist_lat(const void *s) {
  const geometry_msgs_msg_dds__Twist_ *m = s;
  if (nlat < MAXLAT) lat[nlat++] = (wall_ns() / 1e9 - m->linear.y) * 1e3;
}

/* Reads r for secs after its first sample (20 s at most for it): how many. */
static int read_for(dds_entity_t dp, dds_entity_t r, double secs, on_sample f, double *took) {
  dds_entity_t ws = dds_create_waitset(dp);
  dds_entity_t rc = dds_create_readcondition(r, DDS_ANY_STATE);
  dds_waitset_attach(ws, rc, 0);
  double start = 0, end = mono() + 20;
  int n = 0;
  while (mono() < end) {
    dds_waitset_wait(ws, NULL, 0, DDS_MSECS(100));
    int got = take_all(r, start ? f : NULL);
    if (got && !start) {
      start = mono();
      end = start + secs;
      continue;
    }
    n += got;
  }
  *took = start ? mono() - start : 0;
  return n;
}

static sensor_msgs_msg_dds__Image_ image(void) {
  sensor_msgs_msg_dds__Image_ m;
  memset(&m, 0, sizeof m);
  m.height = H;
  m.width = W;
  m.encoding = "bgr8";
  m.step = W * 3;
  m.data._length = m.data._maximum = W * H * 3;
  m.data._buffer = malloc(W * H * 3);
  for (int i = 0; i < W * H * 3; i++) m.data._buffer[i] = (uint8_t)(i % 251);
  return m;
}

static sensor_msgs_msg_dds__LaserScan_ scan(float *ranges) {
  sensor_msgs_msg_dds__LaserScan_ m;
  memset(&m, 0, sizeof m);
  m.angle_min = -1.5707964f;
  m.angle_increment = 0.017453292f;
  m.angle_max = m.angle_min + 179 * m.angle_increment;
  m.range_min = 0.1f;
  m.range_max = 30.0f;
  for (int i = 0; i < 180; i++) ranges[i] = 1.0f + i * 0.01f;
  m.ranges._length = m.ranges._maximum = 180;
  m.ranges._buffer = ranges;
  return m;
}

static void pace(double *next, double period) {
  *next += period;
  double now = mono();
  if (*next > now) dds_sleepfor(DDS_SECS(*next - now));
  else if (now - *next > 0.5) *next = now;
}

int main(int argc, char **argv) {
  if (argc < 4) {
    fprintf(stderr, "usage: %s MODE DOMAIN SECS [ARG [ARG]]\n", argv[0]);
    return 2;
  }
  const char *mode = argv[1];
  double secs = atof(argv[3]);
  const char *arg = argc > 4 ? argv[4] : "";
  dds_entity_t dp = dds_create_participant((dds_domainid_t)atoi(argv[2]), NULL, NULL);
  if (dp < 0) {
    fprintf(stderr, "participant: %s\n", dds_strretcode(-dp));
    return 2;
  }
  setvbuf(stdout, NULL, _IOFBF, 1 << 20);
  lat = calloc(MAXLAT, sizeof *lat);
  double took = 0;
  if (!strcmp(mode, "pub-image")) {
    dds_entity_t w = endpoint(dp, &sensor_msgs_msg_dds__Image__desc, arg, sensor_qos(), 1);
    sensor_msgs_msg_dds__Image_ m = image();
    wait_matched(w);
    double end = mono() + secs, next = mono();
    while (mono() < end) {
      stamp(&m.header, wall_ns(), "camera");
      dds_write(w, &m);
      pace(&next, 0.001);
    }
  } else if (!strcmp(mode, "sub-image")) {
    dds_entity_t r = endpoint(dp, &sensor_msgs_msg_dds__Image__desc, arg, sensor_qos(), 0);
    int n = read_for(dp, r, secs, NULL, &took);
    printf("{\"rate\": %.2f, \"n\": %d}\n", took > 0 ? n / took : 0.0, n);
  } else if (!strcmp(mode, "pub-scan")) {
    dds_entity_t w = endpoint(dp, &sensor_msgs_msg_dds__LaserScan__desc, "rt/scan", sensor_qos(), 1);
    float ranges[180];
    sensor_msgs_msg_dds__LaserScan_ m = scan(ranges);
    wait_matched(w);
    double end = mono() + secs, next = mono();
    for (int k = 1000; mono() < end; k++) {
      ranges[0] = k / 1000.0f;
      int64_t t = wall_ns();
      stamp(&m.header, t, "laser");
      dds_write(w, &m);
      printf("%d %lld\n", k, (long long)t);
      pace(&next, 1.0 / atof(argv[4]));
    }
  } else if (!strcmp(mode, "sub-scan") || !strcmp(mode, "sub-twist")) {
    int twist = !strcmp(mode, "sub-twist");
    dds_entity_t r = twist
        ? endpoint(dp, &geometry_msgs_msg_dds__Twist__desc, "rt/cmd_vel", reliable_qos(), 0)
        : endpoint(dp, &sensor_msgs_msg_dds__LaserScan__desc, "rt/scan", sensor_qos(), 0);
    read_for(dp, r, secs, twist ? twist_lat : scan_lat, &took);
    print_p50(lat, nlat);
  } else if (!strcmp(mode, "pub-twist")) {
    dds_entity_t w = endpoint(dp, &geometry_msgs_msg_dds__Twist__desc, "rt/cmd_vel", reliable_qos(), 1);
    geometry_msgs_msg_dds__Twist_ m;
    memset(&m, 0, sizeof m);
    wait_matched(w);
    double end = mono() + secs, next = mono();
    for (int k = 1; mono() < end; k++) {
      int64_t t = wall_ns();
      m.linear.x = (k % 400 + 1) / 1000.0;
      m.linear.y = t / 1e9;
      dds_write(w, &m);
      printf("%d %lld\n", k % 400 + 1, (long long)t);
      pace(&next, 1.0 / atof(argv[4]));
    }
  } else if (!strcmp(mode, "pub-many")) {
    int img = argc > 5 && atoi(argv[5]);
    dds_entity_t ws = endpoint(dp, &sensor_msgs_msg_dds__LaserScan__desc, "rt/scan", sensor_qos(), 1);
    dds_entity_t wo = endpoint(dp, &nav_msgs_msg_dds__Odometry__desc, "rt/odom", reliable_qos(), 1);
    dds_entity_t wi = img ? endpoint(dp, &sensor_msgs_msg_dds__Image__desc, "rt/varcolorA/image_raw", sensor_qos(), 1) : 0;
    float ranges[180];
    sensor_msgs_msg_dds__LaserScan_ s = scan(ranges);
    sensor_msgs_msg_dds__Image_ im = image();
    nav_msgs_msg_dds__Odometry_ o;
    memset(&o, 0, sizeof o);
    o.child_frame_id = "base_link";
    double end = mono() + secs, next = mono();
    for (int k = 0; mono() < end; k++) {
      int64_t t = wall_ns();
      stamp(&s.header, t, "laser");
      stamp(&o.header, t, "odom");
      o.pose.pose.position.x = k * 0.001;
      o.pose.pose.orientation.w = 1;
      dds_write(ws, &s);
      dds_write(wo, &o);
      if (img) {
        stamp(&im.header, t, "camera");
        dds_write(wi, &im);
      }
      pace(&next, 1.0 / atof(argv[4]));
    }
  } else if (!strcmp(mode, "sub-many")) {
    int img = atoi(arg);
    dds_entity_t rs = endpoint(dp, &sensor_msgs_msg_dds__LaserScan__desc, "rt/scan", sensor_qos(), 0);
    dds_entity_t ro = endpoint(dp, &nav_msgs_msg_dds__Odometry__desc, "rt/odom", reliable_qos(), 0);
    dds_entity_t ri = img ? endpoint(dp, &sensor_msgs_msg_dds__Image__desc, "rt/varcolorA/image_raw", sensor_qos(), 0) : 0;
    int ns = 0, no = 0, ni = 0;
    double end = mono() + secs;
    while (mono() < end) {
      dds_sleepfor(DDS_MSECS(5));
      ns += take_all(rs, NULL);
      no += take_all(ro, NULL);
      if (img) ni += take_all(ri, NULL);
    }
    printf("{\"scan\": %d, \"odom\": %d, \"image\": %d}\n", ns, no, ni);
  } else {
    fprintf(stderr, "unknown mode %s\n", mode);
    return 2;
  }
  fflush(stdout);
  dds_delete(dp);
  return 0;
}
