// A ROS 2 peer on eProsima Fast DDS (Debian's libfastrtps-dev 2.9; the DDS of
// rmw_fastrtps_cpp, ROS 2's default RMW), independent of jderobot's code: the
// messages are ROS 2's (ros2/common_interfaces: sensor_msgs/LaserScan,
// nav_msgs/Odometry, tf2_msgs/TFMessage, geometry_msgs/Twist, sensor_msgs/Image,
// sensor_msgs/Imu) under the DDS names a ROS 2 node uses (topic `rt/scan`, type
// `sensor_msgs::msg::dds_::LaserScan_`), little-endian XCDR1 as rmw_fastrtps writes
// them, with the QoS rclcpp gives them (default: reliable, volatile, keep last 10;
// sensor data: best effort, keep last 5; /tf_static: transient local, keep last 1).
// One TopicDataType carries a message's CDR bytes as they are (so no IDL and no
// fastddsgen); this file decodes and encodes the fields it needs. The endpoints
// are made as rmw_fastrtps_cpp makes them (PREALLOCATED_WITH_REALLOC history, no
// data sharing, an unbounded type without TypeObject), the transports Fast DDS's
// defaults (UDPv4 and shared memory), as in a ROS 2 node.
//
// Compiled by tests/ros2.rs: g++ -std=c++17 fastdds_peer.cpp -lfastrtps -lfastcdr
//
//     fastdds_peer listen DOMAIN SECS   subscribe to a served robot (/scan, /odom,
//                                       /tf, /tf_static, /imu, /colorA/image_raw),
//                                       decode them, drive it on /cmd_vel
//     fastdds_peer robot DOMAIN SECS    be a robot: publish /scan and /odom of a
//                                       robot in a 10 m square room, move as /cmd_vel
//                                       (a reliable reader) says
//     fastdds_peer scans DOMAIN SECS    count /scan's messages (sensor QoS)
//
// As tests/ros2/cyclone_peer.py: the last line on standard output is one JSON
// object (what arrived, decoded). Standard error gets one line per received
// sample (`sample TOPIC N BYTES`, the first 5 of each topic, then every 50th)
// and one per match, unmatch or incompatible QoS, for the test's failure
// messages. FASTDDS_PEER_LOG=warning turns on Fast DDS's own warnings.

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/log/Log.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/DataWriterListener.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/DataReaderListener.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <fastdds/dds/topic/TopicDataType.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastdds/rtps/transport/shared_mem/SharedMemTransportDescriptor.h>
#include <fastrtps/utils/IPLocator.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

using namespace eprosima::fastdds::dds;
using eprosima::fastrtps::rtps::InstanceHandle_t;
using eprosima::fastrtps::rtps::SerializedPayload_t;

// ---------------------------------------------------------------------------
// A message: its serialized payload as it is, the encapsulation header first.

struct Raw {
    std::vector<uint8_t> bytes;
};

// The TopicDataType of one ROS 2 message type: the bytes go through untouched.
class RawType : public TopicDataType {
public:
    explicit RawType(const std::string& name)
    {
        setName(name.c_str());
        // The size a pool buffer starts with; PREALLOCATED_WITH_REALLOC grows it
        // (rmw_fastrtps does the same for an unbounded message).
        m_typeSize = 4 + 1024;
        m_isGetKeyDefined = false;
        auto_fill_type_object(false);
        auto_fill_type_information(false);
    }

    bool serialize(void* data, SerializedPayload_t* payload) override
    {
        auto* m = static_cast<Raw*>(data);
        // The payload was sized by getSerializedSizeProvider.
        if (m->bytes.size() < 4 || payload->max_size < m->bytes.size()) {
            return false;
        }
        std::memcpy(payload->data, m->bytes.data(), m->bytes.size());
        payload->length = static_cast<uint32_t>(m->bytes.size());
        payload->encapsulation = m->bytes[1] == 1 ? CDR_LE : CDR_BE;
        return true;
    }

    bool deserialize(SerializedPayload_t* payload, void* data) override
    {
        auto* m = static_cast<Raw*>(data);
        m->bytes.assign(payload->data, payload->data + payload->length);
        return true;
    }

    std::function<uint32_t()> getSerializedSizeProvider(void* data) override
    {
        auto* m = static_cast<Raw*>(data);
        return [m]() { return static_cast<uint32_t>(m->bytes.size()); };
    }

    void* createData() override { return new Raw(); }

    void deleteData(void* data) override { delete static_cast<Raw*>(data); }

    bool getKey(void*, InstanceHandle_t*, bool) override { return false; }
};

// ---------------------------------------------------------------------------
// XCDR1 little-endian: alignment counted from the end of the 4-byte header.

struct CdrIn {
    const std::vector<uint8_t>& b;
    size_t pos = 4;
    bool ok = true;

    explicit CdrIn(const std::vector<uint8_t>& bytes) : b(bytes)
    {
        ok = b.size() >= 4 && b[0] == 0 && b[1] == 1;  // CDR_LE
    }

    void align(size_t n)
    {
        size_t off = pos - 4;
        pos += (n - off % n) % n;
    }

    template <typename T>
    T get()
    {
        align(sizeof(T));
        T v{};
        if (!ok || pos + sizeof(T) > b.size()) {
            ok = false;
            return v;
        }
        std::memcpy(&v, &b[pos], sizeof(T));
        pos += sizeof(T);
        return v;
    }

    std::string str()
    {
        uint32_t n = get<uint32_t>();
        if (!ok || n == 0 || pos + n > b.size()) {
            ok = ok && n == 0;
            return "";
        }
        std::string s(reinterpret_cast<const char*>(&b[pos]), n - 1);  // without its NUL
        pos += n;
        return s;
    }

    void skip_f64(size_t n)
    {
        for (size_t i = 0; i < n; i++) {
            get<double>();
        }
    }
};

struct CdrOut {
    std::vector<uint8_t> b{0, 1, 0, 0};  // CDR_LE, no options

    void align(size_t n)
    {
        while ((b.size() - 4) % n) {
            b.push_back(0);
        }
    }

    template <typename T>
    void put(T v)
    {
        align(sizeof(T));
        size_t at = b.size();
        b.resize(at + sizeof(T));
        std::memcpy(&b[at], &v, sizeof(T));
    }

    void str(const std::string& s)
    {
        put<uint32_t>(static_cast<uint32_t>(s.size() + 1));
        b.insert(b.end(), s.begin(), s.end());
        b.push_back(0);
    }

    void header(double t, const std::string& frame)
    {
        put<int32_t>(static_cast<int32_t>(t));
        put<uint32_t>(static_cast<uint32_t>((t - std::floor(t)) * 1e9));
        str(frame);
    }
};

// ---------------------------------------------------------------------------
// JSON, by hand.

static std::string q(const std::string& s)
{
    std::string o = "\"";
    for (char c : s) {
        if (c == '"' || c == '\\') {
            o += '\\';
            o += c;
        } else if (static_cast<unsigned char>(c) < 0x20) {
            char u[8];
            std::snprintf(u, sizeof u, "\\u%04x", c);
            o += u;
        } else {
            o += c;
        }
    }
    return o + "\"";
}

static std::string num(double v)
{
    if (!std::isfinite(v)) {
        return "null";
    }
    char s[32];
    std::snprintf(s, sizeof s, "%.17g", v);
    return s;
}

// An object built field by field: obj().f("x", 1.0).s("frame", "odom").str()
struct Obj {
    std::string body;
    Obj& raw(const char* k, const std::string& v)
    {
        body += (body.empty() ? "" : ", ") + q(k) + ": " + v;
        return *this;
    }
    Obj& f(const char* k, double v) { return raw(k, num(v)); }
    Obj& s(const char* k, const std::string& v) { return raw(k, q(v)); }
    std::string str() const { return "{" + body + "}"; }
};

static double now()
{
    using namespace std::chrono;
    return duration<double>(system_clock::now().time_since_epoch()).count();
}

static double yaw(double z, double w) { return 2.0 * std::atan2(z, w); }

// ---------------------------------------------------------------------------
// Endpoints, with rclcpp's QoS.

enum class Q { Default, Sensor, Static };

static void apply(Q q, ReliabilityQosPolicy& rel, DurabilityQosPolicy& dur, HistoryQosPolicy& hist)
{
    rel.kind = q == Q::Sensor ? BEST_EFFORT_RELIABILITY_QOS : RELIABLE_RELIABILITY_QOS;
    dur.kind = q == Q::Static ? TRANSIENT_LOCAL_DURABILITY_QOS : VOLATILE_DURABILITY_QOS;
    hist.kind = KEEP_LAST_HISTORY_QOS;
    hist.depth = q == Q::Sensor ? 5 : q == Q::Static ? 1 : 10;
}

// ROS 2's "this host only", as rmw_fastrtps sets it up from the same variables:
// Humble's ROS_LOCALHOST_ONLY=1 is a UDPv4 transport on 127.0.0.1 alone (so
// discovery's multicast on the loopback interface) and shared memory; Jazzy's and
// Kilted's ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST is no multicast at all:
// discovery by unicast to 127.0.0.1's participant ports (32 of them), Fast DDS's
// UDPv4 transport otherwise as it is (every interface's address announced) and
// shared memory. Without either: Fast DDS's defaults (multicast discovery on
// every interface, UDPv4 and shared memory), ROS 2's SUBNET.
static void keep_to_this_host(DomainParticipantQos& qos)
{
    using namespace eprosima::fastdds::rtps;
    using eprosima::fastrtps::rtps::IPLocator;
    using eprosima::fastrtps::rtps::Locator_t;
    auto env = [](const char* k) {
        const char* v = std::getenv(k);
        return std::string(v ? v : "");
    };
    if (env("ROS_LOCALHOST_ONLY") == "1") {
        std::fprintf(stderr, "ROS_LOCALHOST_ONLY=1: UDPv4 on 127.0.0.1 only, and shared memory\n");
        qos.transport().use_builtin_transports = false;
        auto udp = std::make_shared<UDPv4TransportDescriptor>();
        udp->interfaceWhiteList.emplace_back("127.0.0.1");
        qos.transport().user_transports.push_back(udp);
        qos.transport().user_transports.push_back(std::make_shared<SharedMemTransportDescriptor>());
    } else if (env("ROS_AUTOMATIC_DISCOVERY_RANGE") == "LOCALHOST") {
        std::fprintf(stderr, "ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST: no multicast, "
                             "discovery by unicast to 127.0.0.1\n");
        qos.wire_protocol().builtin.metatrafficMulticastLocatorList.clear();
        qos.wire_protocol().builtin.metatrafficUnicastLocatorList.push_back(Locator_t());
        qos.transport().use_builtin_transports = false;
        qos.transport().user_transports.push_back(std::make_shared<SharedMemTransportDescriptor>());
        auto udp = std::make_shared<UDPv4TransportDescriptor>();
        udp->maxInitialPeersRange = 32;
        qos.transport().user_transports.push_back(udp);
        Locator_t peer;
        IPLocator::setIPv4(peer, "127.0.0.1");
        qos.wire_protocol().builtin.initialPeersList.push_back(peer);
    }
}

// Says on standard error when an endpoint matches, unmatches, or is refused.
class Listener : public DataReaderListener, public DataWriterListener {
public:
    explicit Listener(std::string topic) : topic_(std::move(topic)) {}
    std::atomic<int> matched{0};
    std::atomic<int> incompatible{0};

    void on_subscription_matched(DataReader*, const SubscriptionMatchedStatus& s) override
    {
        matched = s.current_count;
        std::fprintf(stderr, "reader %s matched %d writer(s)\n", topic_.c_str(), s.current_count);
    }
    void on_requested_incompatible_qos(DataReader*, const RequestedIncompatibleQosStatus& s) override
    {
        incompatible++;
        std::fprintf(stderr, "reader %s: incompatible QoS, policy %u\n", topic_.c_str(),
                     static_cast<unsigned>(s.last_policy_id));
    }
    void on_sample_lost(DataReader*, const SampleLostStatus& s) override
    {
        std::fprintf(stderr, "reader %s: %d sample(s) lost\n", topic_.c_str(), s.total_count);
    }
    void on_sample_rejected(DataReader*, const SampleRejectedStatus& s) override
    {
        std::fprintf(stderr, "reader %s: %u sample(s) rejected\n", topic_.c_str(), s.total_count);
    }
    void on_publication_matched(DataWriter*, const PublicationMatchedStatus& s) override
    {
        matched = s.current_count;
        std::fprintf(stderr, "writer %s matched %d reader(s)\n", topic_.c_str(), s.current_count);
    }
    void on_offered_incompatible_qos(DataWriter*, const OfferedIncompatibleQosStatus& s) override
    {
        incompatible++;
        std::fprintf(stderr, "writer %s: incompatible QoS, policy %u\n", topic_.c_str(),
                     static_cast<unsigned>(s.last_policy_id));
    }

private:
    std::string topic_;
};

struct Node {
    DomainParticipant* dp = nullptr;
    Publisher* pub = nullptr;
    Subscriber* sub = nullptr;
    std::map<std::string, TypeSupport> types;
    std::vector<std::unique_ptr<Listener>> listeners;

    explicit Node(int domain)
    {
        DomainParticipantQos qos = PARTICIPANT_QOS_DEFAULT;
        qos.name("fastdds_peer");
        keep_to_this_host(qos);
        dp = DomainParticipantFactory::get_instance()->create_participant(domain, qos);
        if (!dp) {
            std::fprintf(stderr, "no Fast DDS participant in domain %d\n", domain);
            std::exit(2);
        }
        pub = dp->create_publisher(PUBLISHER_QOS_DEFAULT);
        sub = dp->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
    }

    ~Node()
    {
        dp->delete_contained_entities();
        DomainParticipantFactory::get_instance()->delete_participant(dp);
    }

    // The DDS topic of ROS 2 topic `ros` (`scan` -> `rt/scan`) of message `msg`
    // (`sensor_msgs/LaserScan` -> `sensor_msgs::msg::dds_::LaserScan_`).
    Topic* topic(const std::string& ros, const std::string& msg)
    {
        auto slash = msg.find('/');
        std::string tn = msg.substr(0, slash) + "::msg::dds_::" + msg.substr(slash + 1) + "_";
        if (!types.count(tn)) {
            TypeSupport ts(new RawType(tn));
            ts.register_type(dp);
            types.emplace(tn, ts);
        }
        std::string name = "rt/" + ros;
        if (auto* t = dynamic_cast<Topic*>(dp->lookup_topicdescription(name))) {
            return t;
        }
        return dp->create_topic(name, tn, TOPIC_QOS_DEFAULT);
    }

    DataReader* reader(const std::string& ros, const std::string& msg, Q qos)
    {
        DataReaderQos rq = sub->get_default_datareader_qos();
        apply(qos, rq.reliability(), rq.durability(), rq.history());
        rq.endpoint().history_memory_policy =
            eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
        rq.data_sharing().off();
        listeners.emplace_back(new Listener("rt/" + ros));
        auto* r = sub->create_datareader(topic(ros, msg), rq, listeners.back().get());
        if (!r) {
            std::fprintf(stderr, "no reader of %s\n", ros.c_str());
            std::exit(2);
        }
        return r;
    }

    DataWriter* writer(const std::string& ros, const std::string& msg, Q qos)
    {
        DataWriterQos wq = pub->get_default_datawriter_qos();
        apply(qos, wq.reliability(), wq.durability(), wq.history());
        wq.endpoint().history_memory_policy =
            eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
        wq.data_sharing().off();
        listeners.emplace_back(new Listener("rt/" + ros));
        auto* w = pub->create_datawriter(topic(ros, msg), wq, listeners.back().get());
        if (!w) {
            std::fprintf(stderr, "no writer of %s\n", ros.c_str());
            std::exit(2);
        }
        return w;
    }
};

// Takes what `r` holds; one line on standard error per sample (the first 5,
// then every 50th), each counted in `counts[name]`.
static std::vector<Raw> take(DataReader* r, const std::string& name, std::map<std::string, int>& counts)
{
    std::vector<Raw> out;
    Raw m;
    SampleInfo info;
    while (r->take_next_sample(&m, &info) == ReturnCode_t::RETCODE_OK) {
        if (!info.valid_data) {
            continue;
        }
        int n = ++counts[name];
        if (n <= 5 || n % 50 == 0) {
            std::fprintf(stderr, "sample %s %d %zu\n", name.c_str(), n, m.bytes.size());
        }
        out.push_back(std::move(m));
        m = Raw();
    }
    return out;
}

static std::string counts_json(const std::map<std::string, int>& counts)
{
    Obj o;
    for (auto& [k, v] : counts) {
        o.f(k.c_str(), v);
    }
    return o.str();
}

// ---------------------------------------------------------------------------

static int listen(int domain, double secs)
{
    Node node(domain);
    struct R {
        std::string name;
        DataReader* r;
    };
    std::vector<R> readers = {
        {"scan", node.reader("scan", "sensor_msgs/LaserScan", Q::Sensor)},
        {"odom", node.reader("odom", "nav_msgs/Odometry", Q::Default)},
        {"tf", node.reader("tf", "tf2_msgs/TFMessage", Q::Default)},
        {"tf_static", node.reader("tf_static", "tf2_msgs/TFMessage", Q::Static)},
        {"image", node.reader("colorA/image_raw", "sensor_msgs/Image", Q::Sensor)},
        {"imu", node.reader("imu", "sensor_msgs/Imu", Q::Sensor)},
    };
    DataWriter* cmd = node.writer("cmd_vel", "geometry_msgs/Twist", Q::Default);
    std::map<std::string, std::string> got;
    std::map<std::string, int> counts;
    bool have_first = false;
    double x0 = 0, y0 = 0, x = 0, y = 0;
    int cmds = 0, bad = 0;
    double end = now() + secs;
    while (now() < end) {
        if (have_first) {  // drive once the starting pose is known
            CdrOut t;
            for (double v : {0.3, 0.0, 0.0, 0.0, 0.0, 0.2}) {
                t.put<double>(v);
            }
            Raw m{t.b};
            if (cmd->write(&m)) {
                cmds++;
            }
        }
        for (auto& [name, r] : readers) {
            for (auto& m : take(r, name, counts)) {
                CdrIn c(m.bytes);
                double sec = c.get<int32_t>();
                c.get<uint32_t>();
                std::string frame = c.str();
                Obj o;
                o.s("frame", frame);
                if (name == "scan") {
                    float amin = c.get<float>(), amax = c.get<float>(), inc = c.get<float>();
                    c.get<float>();
                    c.get<float>();
                    float rmin = c.get<float>(), rmax = c.get<float>();
                    uint32_t n = c.get<uint32_t>();
                    std::vector<float> ranges;
                    for (uint32_t i = 0; i < n && c.ok; i++) {
                        ranges.push_back(c.get<float>());
                    }
                    uint32_t ni = c.get<uint32_t>();
                    o.f("stamp", sec).f("n", n).f("angle_min", amin).f("angle_max", amax)
                        .f("angle_increment", inc).f("range_min", rmin).f("range_max", rmax)
                        .f("intensities", ni);
                    if (!ranges.empty()) {
                        o.raw("ranges", "[" + num(ranges[0]) + ", " + num(ranges[ranges.size() / 2]) + "]");
                    }
                } else if (name == "odom") {
                    std::string child = c.str();
                    double px = c.get<double>(), py = c.get<double>();
                    c.get<double>();
                    c.get<double>();
                    c.get<double>();
                    double qz = c.get<double>(), qw = c.get<double>();
                    o.s("child", child).f("x", px).f("y", py).f("yaw", yaw(qz, qw));
                    if (c.ok && !have_first) {
                        have_first = true;
                        x0 = px;
                        y0 = py;
                        got["odom_first"] = o.str();
                    }
                    x = px;
                    y = py;
                } else if (name == "tf" || name == "tf_static") {
                    // TFMessage: a sequence of TransformStamped; the header read
                    // above was the sequence's length and the first one's stamp.
                    CdrIn t(m.bytes);
                    uint32_t n = t.get<uint32_t>();
                    t.get<int32_t>();
                    t.get<uint32_t>();
                    std::string parent = t.str(), child = t.str();
                    double tx = t.get<double>(), ty = t.get<double>();
                    t.get<double>();
                    t.get<double>();
                    t.get<double>();
                    double qz = t.get<double>(), qw = t.get<double>();
                    o = Obj();
                    o.s("parent", parent).s("child", child).f("x", tx).f("y", ty)
                        .f("yaw", yaw(qz, qw)).f("n", n);
                    c.ok = t.ok;
                } else if (name == "image") {
                    uint32_t h = c.get<uint32_t>(), w = c.get<uint32_t>();
                    std::string enc = c.str();
                    uint8_t big = c.get<uint8_t>();
                    uint32_t step = c.get<uint32_t>(), bytes = c.get<uint32_t>();
                    o.f("width", w).f("height", h).s("encoding", enc).f("step", step)
                        .f("bytes", bytes).f("big", big);
                    c.ok = c.ok && c.pos + bytes <= m.bytes.size();
                } else if (name == "imu") {
                    double qx = c.get<double>(), qy = c.get<double>(), qz = c.get<double>();
                    double qw = c.get<double>();
                    c.skip_f64(9 + 3 + 9 + 2);
                    double az = c.get<double>();
                    o.f("qx", qx).f("qy", qy).f("qz", qz).f("qw", qw).f("az", az);
                }
                if (!c.ok) {
                    bad++;
                    std::fprintf(stderr, "%s: a message that does not decode (%zu bytes)\n",
                                 name.c_str(), m.bytes.size());
                    continue;
                }
                got[name] = o.str();
            }
        }
        bool all = true;
        for (auto k : {"scan", "odom", "tf", "tf_static", "image", "imu"}) {
            all = all && got.count(k);
        }
        if (all && std::hypot(x - x0, y - y0) > 0.1 && counts["scan"] >= 5) {
            break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    Obj out;
    for (auto& [k, v] : got) {
        out.raw(k.c_str(), v);
    }
    out.raw("counts", counts_json(counts)).f("cmds", cmds).f("bad", bad);
    std::printf("%s\n", out.str().c_str());
    std::fflush(stdout);
    return 0;
}

// A robot in a 10 m square room (walls at x, y = +-5 m), starting at the origin
// facing +x; it moves as /cmd_vel says (unicycle, 20 Hz). /cmd_vel is read with
// rclcpp's default QoS (reliable), as a robot base's driver does.
static int robot(int domain, double secs)
{
    Node node(domain);
    DataWriter* scan_w = node.writer("scan", "sensor_msgs/LaserScan", Q::Sensor);
    DataWriter* odom_w = node.writer("odom", "nav_msgs/Odometry", Q::Default);
    DataReader* cmd_r = node.reader("cmd_vel", "geometry_msgs/Twist", Q::Default);
    std::map<std::string, int> counts;
    double x = 0, y = 0, th = 0, v = 0, w = 0, max_v = 0, max_w = 0, last_v = 0, last_w = 0;
    int cmds = 0, bad = 0, scans = 0, odoms = 0;
    double start = now(), last_cmd = now(), end = now() + secs, first_cmd = -1;
    const int n = 181;
    const double inc = M_PI / 180.0;
    while (now() < end) {
        for (auto& m : take(cmd_r, "cmd_vel", counts)) {
            CdrIn c(m.bytes);
            double lx = c.get<double>();
            c.get<double>();
            c.get<double>();
            c.get<double>();
            c.get<double>();
            double az = c.get<double>();
            if (!c.ok || !std::isfinite(lx) || !std::isfinite(az)) {
                bad++;
                continue;
            }
            v = last_v = lx;
            w = last_w = az;
            if (cmds++ == 0) {
                first_cmd = now() - start;
            }
            max_v = std::max(max_v, v);
            max_w = std::max(max_w, std::fabs(w));
            last_cmd = now();
        }
        if (now() - last_cmd > 0.5) {
            v = w = 0;
        }
        const double dt = 0.05;
        x += v * std::cos(th) * dt;
        y += v * std::sin(th) * dt;
        th += w * dt;
        double t = now();
        CdrOut s;
        s.header(t, "base_scan");
        for (double f : {-M_PI / 2, M_PI / 2, inc, 0.0, 0.05, 0.12, 8.0}) {
            s.put<float>(static_cast<float>(f));
        }
        s.put<uint32_t>(n);
        for (int i = 0; i < n; i++) {
            double a = th - M_PI / 2 + i * inc, ca = std::cos(a), sa = std::sin(a);
            double d = 1e9;
            if (ca > 1e-9) d = std::min(d, (5.0 - x) / ca);
            if (ca < -1e-9) d = std::min(d, (-5.0 - x) / ca);
            if (sa > 1e-9) d = std::min(d, (5.0 - y) / sa);
            if (sa < -1e-9) d = std::min(d, (-5.0 - y) / sa);
            s.put<float>(static_cast<float>(std::min(d, 8.0)));
        }
        s.put<uint32_t>(0);  // no intensities
        Raw sm{s.b};
        scans += scan_w->write(&sm) ? 1 : 0;
        CdrOut o;
        o.header(t, "odom");
        o.str("base_footprint");
        for (double f : {x, y, 0.0, 0.0, 0.0, std::sin(th / 2), std::cos(th / 2)}) {
            o.put<double>(f);
        }
        for (int i = 0; i < 36; i++) o.put<double>(0.0);
        for (double f : {v, 0.0, 0.0, 0.0, 0.0, w}) o.put<double>(f);
        for (int i = 0; i < 36; i++) o.put<double>(0.0);
        Raw om{o.b};
        odoms += odom_w->write(&om) ? 1 : 0;
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
        if (cmds > 0 && x > 2.0) {
            break;
        }
    }
    std::printf("%s\n", Obj().f("x", x).f("y", y).f("theta", th).f("cmds", cmds).f("max_v", max_v)
                            .f("max_w", max_w).f("last_v", last_v).f("last_w", last_w)
                            .f("bad", bad).f("scans_sent", scans).f("odoms_sent", odoms)
                            .raw("first_cmd_s", first_cmd < 0 ? "null" : num(first_cmd))
                            .str().c_str());
    std::fflush(stdout);
    return 0;
}

static int scans(int domain, double secs)
{
    Node node(domain);
    DataReader* r = node.reader("scan", "sensor_msgs/LaserScan", Q::Sensor);
    std::map<std::string, int> counts;
    double start = now(), first = -1;
    while (now() < start + secs) {
        if (!take(r, "scan", counts).empty() && first < 0) {
            first = now() - start;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    std::printf("%s\n", Obj().f("scans", counts["scan"]).raw("first_s", first < 0 ? "null" : num(first))
                            .str().c_str());
    std::fflush(stdout);
    return 0;
}

int main(int argc, char** argv)
{
    if (argc < 4) {
        std::fprintf(stderr, "usage: %s listen|robot|scans DOMAIN SECS\n", argv[0]);
        return 2;
    }
    if (const char* l = std::getenv("FASTDDS_PEER_LOG"); l && std::string(l) == "warning") {
        Log::SetVerbosity(Log::Kind::Warning);
    }
    std::string mode = argv[1];
    int domain = std::atoi(argv[2]);
    double secs = std::atof(argv[3]);
    int rc = mode == "listen" ? listen(domain, secs)
           : mode == "robot"  ? robot(domain, secs)
           : mode == "scans"  ? scans(domain, secs)
                              : 2;
    Log::Flush();
    return rc;
}
