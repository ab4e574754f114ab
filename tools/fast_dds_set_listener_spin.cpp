// Does Fast DDS's DomainParticipant::set_listener(nullptr) wait for a listener callback in
// progress, or spin for good?
//
// rmw_fastrtps's destroy_participant (every rclpy node's teardown) begins with
// set_listener(nullptr), whose default timeout is infinite. With a participant listener
// callback in progress, Fast DDS 2.14 as shipped in the Jazzy wheels busy-waits on its
// condition variable (eProsima/Fast-DDS#6513) while holding the listener mutex nearly all the
// time; the callback, once done, needs that mutex to say so, and does not get it: the teardown
// never ends. With a finite timeout the same call blocks and returns when the callback ends.
//
// Two participants in this process (loopback UDP and shared memory only, domain 97); the
// first's listener sleeps 1.5 s when it learns that a participant left. The second is
// deleted, and while the first's callback runs, the main thread calls
// set_listener(nullptr) (no argument) or set_listener(nullptr, N s) (argument N), and a
// watcher prints the main thread's CPU time every 0.5 s. Built and run by
// tools/fast_dds_set_listener_spin.sh (the .venv's Fast DDS headers and libraries).
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/DomainParticipantListener.hpp>
#include <fastdds/rtps/transport/UDPv4TransportDescriptor.h>
#include <fastdds/rtps/transport/shared_mem/SharedMemTransportDescriptor.h>
#include <pthread.h>
#include <time.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <thread>

using eprosima::fastdds::dds::DomainParticipant;
using eprosima::fastdds::dds::DomainParticipantFactory;
using eprosima::fastdds::dds::DomainParticipantListener;
using eprosima::fastdds::dds::DomainParticipantQos;
using eprosima::fastrtps::rtps::ParticipantDiscoveryInfo;

static std::atomic<bool> in_callback{false};

// Sleeps 1.5 s in the callback that tells of a participant leaving.
struct SlowListener : DomainParticipantListener
{
    void on_participant_discovery(DomainParticipant*, ParticipantDiscoveryInfo&& info) override
    {
        if (info.status == ParticipantDiscoveryInfo::REMOVED_PARTICIPANT ||
                info.status == ParticipantDiscoveryInfo::DROPPED_PARTICIPANT)
        {
            in_callback = true;
            std::this_thread::sleep_for(std::chrono::milliseconds(1500));
            in_callback = false;
        }
    }
};

static double seconds_of(clockid_t clock)
{
    timespec t;
    clock_gettime(clock, &t);
    return t.tv_sec + t.tv_nsec * 1e-9;
}

// Loopback only: UDP on 127.0.0.1 and shared memory, the initial peer 127.0.0.1.
static DomainParticipantQos loopback_qos()
{
    DomainParticipantQos qos = eprosima::fastdds::dds::PARTICIPANT_QOS_DEFAULT;
    qos.transport().use_builtin_transports = false;
    auto udp = std::make_shared<eprosima::fastdds::rtps::UDPv4TransportDescriptor>();
    udp->interfaceWhiteList.push_back("127.0.0.1");
    qos.transport().user_transports.push_back(udp);
    qos.transport().user_transports.push_back(
        std::make_shared<eprosima::fastdds::rtps::SharedMemTransportDescriptor>());
    eprosima::fastrtps::rtps::Locator_t peer;
    eprosima::fastrtps::rtps::IPLocator::setIPv4(peer, 127, 0, 0, 1);
    qos.wire_protocol().builtin.initialPeersList.push_back(peer);
    return qos;
}

int main(int argc, char** argv)
{
    setvbuf(stdout, nullptr, _IONBF, 0);
    const int timeout_s = argc > 1 ? std::atoi(argv[1]) : 0;   // 0: the default (infinite)
    clockid_t main_cpu;
    pthread_getcpuclockid(pthread_self(), &main_cpu);
    auto* factory = DomainParticipantFactory::get_instance();
    SlowListener slow;
    auto* watched = factory->create_participant(97, loopback_qos(), &slow);
    auto* leaving = factory->create_participant(97, loopback_qos());
    std::this_thread::sleep_for(std::chrono::seconds(2));      // discovery
    std::thread remover([&] { factory->delete_participant(leaving); });
    for (int i = 0; i < 300 && !in_callback; ++i)
    {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    std::printf("callback in progress: %s; set_listener(nullptr%s)\n", in_callback ? "yes" : "no",
                timeout_s ? (", " + std::to_string(timeout_s) + " s").c_str() : "");
    const double cpu0 = seconds_of(main_cpu), wall0 = seconds_of(CLOCK_MONOTONIC);
    std::atomic<bool> done{false};
    std::thread watcher([&] {
        while (!done)
        {
            std::this_thread::sleep_for(std::chrono::milliseconds(500));
            if (!done)
            {
                std::printf("  %5.1f s in set_listener: main thread CPU %.3f s, callback in progress: %s\n",
                            seconds_of(CLOCK_MONOTONIC) - wall0, seconds_of(main_cpu) - cpu0,
                            in_callback ? "yes" : "no");
            }
        }
    });
    const auto rc = timeout_s ? watched->set_listener(nullptr, std::chrono::seconds(timeout_s))
                              : watched->set_listener(nullptr);
    const double wall = seconds_of(CLOCK_MONOTONIC) - wall0, cpu = seconds_of(main_cpu) - cpu0;
    done = true;
    watcher.join();
    std::printf("set_listener returned %d after %.3f s; main thread CPU %.3f s\n", static_cast<int>(rc()),
                wall, cpu);
    remover.join();
    factory->delete_participant(watched);
    return 0;
}
