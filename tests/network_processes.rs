//! Two real `jderobot` processes on loopback: one runs the simulator and
//! networkserver, the other networkclient and introrob (headless). introrob drives
//! the remote robot, images and laser arrive, `ps` shows the remote interfaces'
//! rates; when the server process goes away they turn stale and come back with a
//! new server process.
#![cfg(all(
    feature = "networkserver",
    feature = "networkclient",
    feature = "simulator",
    feature = "introrob"
))]

use crate::common;

use common::process::{Proc, free_port, rate};

#[test]
fn introrob_drives_a_robot_served_by_another_process() {
    let dir = tempfile::tempdir().unwrap();
    let world = common::world_path("simple.world");
    let port = free_port();
    let server_conf = dir.path().join("robot.conf");
    std::fs::write(
        &server_conf,
        format!(
            "driver simulator\nworld {world}\nrobot robot1 1000 1000 90\nprovides encoders\nprovides motors\n\
             provides laser 180 1\nprovides sonars\nprovides colorA\nend_driver\n\
             driver networkserver\nsocket {port}\nserves colorA 0\nserves laser\nserves sonars\n\
             serves encoders\nserves motors\nend_driver\n\
             load_driver simulator\nload_service networkserver\n"
        ),
    )
    .unwrap();
    let client_conf = dir.path().join("gui.conf");
    let h = format!("127.0.0.1 {port}");
    std::fs::write(
        &client_conf,
        format!(
            "driver networkclient\nprovides colorA {h} 0\nprovides laser {h}\nprovides sonars {h}\n\
             provides encoders {h}\nprovides motors {h}\nend_driver\n\
             schema introrob\nbehaviour vff\ntarget 5000 2200\nmax_v 400\nworld {world}\nend_schema\n\
             load_driver networkclient\nload_schema introrob\nrun introrob\n"
        ),
    )
    .unwrap();

    let mut robot = Proc::start(&server_conf);
    let start = robot.ask_until("echo encoders", "the robot's pose", |l| {
        l.starts_with("encoders clock=")
    });
    let mut gui = Proc::start(&client_conf);
    // The remote interfaces arrive at their rates.
    gui.expect_arriving(&["laser", "colorA", "encoders"], "networkclient");
    robot.expect_moved(&start, 150.0);
    robot.quit();
    // The server is gone: stale, with the reason.
    let l = gui.ask_until("ps", "laser stale", |l| {
        l.starts_with("laser: ") && l.contains("STALE")
    });
    assert!(l.contains(&port.to_string()), "{l}");
    // A new server process on the same port: the client resubscribes.
    let mut robot = Proc::start(&server_conf);
    gui.ask_until("ps", "laser fresh again", |l| {
        l.starts_with("laser: ") && !l.contains("STALE") && rate(l) >= 3.0
    });
    gui.quit();
    robot.send("echo motors");
    robot.quit();
}
