use std::{
  io,
  net::{IpAddr, Ipv4Addr, SocketAddr},
  sync::atomic::{AtomicBool, Ordering},
};

use log::error;
use pnet::datalink::NetworkInterface;

use crate::structure::locator::Locator;

/// jderobot's patch: RTPS kept to this host, as ROS 2's
/// `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST` (rmw_cyclonedds's localhost mode:
/// the loopback interface with multicast): multicast joined and sent on the
/// loopback interface only, unicast listeners bound to 127.0.0.1, only loopback
/// locators announced, nothing sent to another address. One setting per process
/// (every participant shares it), set before the first participant is made.
static LOCALHOST_ONLY: AtomicBool = AtomicBool::new(false);

/// Keeps every participant made from now on to this host (or not).
pub fn set_localhost_only(on: bool) {
  LOCALHOST_ONLY.store(on, Ordering::Release);
}

/// Whether RTPS is kept to this host ([`set_localhost_only`]).
pub fn localhost_only() -> bool {
  LOCALHOST_ONLY.load(Ordering::Acquire)
}

pub fn get_local_multicast_locators(port: u16) -> Vec<Locator> {
  let saddr = SocketAddr::new("239.255.0.1".parse().unwrap(), port);
  vec![Locator::from(saddr)]
}

pub fn get_local_unicast_locators(port: u16) -> Vec<Locator> {
  if localhost_only() {
    return vec![Locator::from(SocketAddr::new(Ipv4Addr::LOCALHOST.into(), port))];
  }
  match if_addrs::get_if_addrs() {
    Ok(ifaces) => {
      let addrs: Vec<Locator> = ifaces
        .iter()
        .filter(|ip| !ip.is_loopback())
        .map(|ip| Locator::from(SocketAddr::new(ip.ip(), port)))
        .collect();
      // jderobot's patch: on a host whose only interface is loopback (a robot's
      // computer without a network, a sandbox) the participant is reachable on
      // loopback, as in localhost mode; it announced no address at all before.
      if addrs.is_empty() {
        return vec![Locator::from(SocketAddr::new(Ipv4Addr::LOCALHOST.into(), port))];
      }
      addrs
    }
    Err(e) => {
      error!("Cannot get local network interfaces: get_if_addrs() : {e:?}");
      vec![]
    }
  }
}

/// Enumerates local interfaces that we may use for multicasting.
///
/// The result of this function is used to set up senders and listeners.
pub fn get_local_multicast_ip_addrs() -> io::Result<Vec<IpAddr>> {
  if localhost_only() {
    return Ok(vec![Ipv4Addr::LOCALHOST.into()]);
  }
  // grab a list of system intefaces.
  //
  // note: `pnet` works on mac, windows, and linux, potentially alongside
  // other systems.
  let interfaces = pnet::datalink::interfaces();

  // grab all the ips from each interface
  let addrs = get_local_multicast_ip_addrs_inner(interfaces);
  // jderobot's patch: no multicast interface but loopback: multicast on loopback,
  // as in localhost mode (it sent no discovery at all before).
  if addrs.is_empty() {
    return Ok(vec![Ipv4Addr::LOCALHOST.into()]);
  }
  Ok(addrs)
}

/// Inner implementation of [`get_local_multicast_ip_addrs`], for testing
/// purposes.
fn get_local_multicast_ip_addrs_inner(interfaces: Vec<NetworkInterface>) -> Vec<IpAddr> {
  interfaces
    .into_iter()
    .filter(|ifaddr| !ifaddr.is_loopback()) // don't use lo interface
    .filter(|ifaddr| ifaddr.is_multicast()) // require support for multicast
    .flat_map(|ifaddr| ifaddr.ips)
    .map(|ip_net| ip_net.ip()) // get the ip from each ip network
    .filter(|ip| ip.is_ipv4()) // use ipv4 only :(
    .collect::<Vec<_>>()
}

#[cfg(test)]
mod tests {
  use std::{
    ffi::c_int,
    net::{Ipv4Addr, Ipv6Addr},
  };

  use pnet::{
    datalink::{InterfaceType, NetworkInterface},
    ipnetwork::{IpNetwork, Ipv4Network, Ipv6Network},
  };

  /// Mocks the `get_local_multicast_ip_addrs` function.
  #[test]
  fn test_get_local_multicast_ip_addrs() {
    let eth0 = interface(
      "eth0",
      1,
      &[
        IpNetwork::V4(Ipv4Network::new(Ipv4Addr::new(192, 168, 0, 137), 24).unwrap()),
        IpNetwork::V6(
          Ipv6Network::new(Ipv6Addr::new(0xfd73, 0x40a2, 0x1c3e, 0, 0, 0, 0, 0), 64).unwrap(),
        ),
      ],
      &[pnet_sys::IFF_MULTICAST],
    );

    let interfaces = vec![loopback(), eth0];

    let ips = super::get_local_multicast_ip_addrs_inner(interfaces);

    // TODO: uncomment if IPv6 becomes supported :(
    // assert_eq!(ips.len(), 2, "should only contain the non-loopback iface");
    assert_eq!(ips.len(), 1, "should only contain the non-loopback iface");
    assert!(ips.contains(&Ipv4Addr::new(192, 168, 0, 137).into()));

    // TODO: uncomment if ipv6
    // assert!(ips.contains(&Ipv6Addr::new(0xfd73, 0x40a2, 0x1c3e, 0, 0, 0, 0,
    // 0).into()))
  }

  /// Tries a number of interfaces, none of which support multicast.
  ///
  /// This should result in an empty list of IP addresses.
  #[test]
  fn no_multicast() {
    let mut interfaces = Vec::new();

    for index in 0..10 {
      interfaces.push(interface(
        format!("eth{index}"),
        index,
        &[IpNetwork::V4(
          Ipv4Network::new(Ipv4Addr::new(192, 168, 0, rand::random()), 24).unwrap(),
        )],
        &[],
      ));
    }

    let ips = super::get_local_multicast_ip_addrs_inner(interfaces);

    assert!(
      ips.is_empty(),
      "we only want interfaces w/ multicast support"
    );
  }

  #[test]
  fn empty_interfaces() {
    let ips = super::get_local_multicast_ip_addrs_inner(Vec::new());
    assert!(
      ips.is_empty(),
      "blank iface list should result in empty list of ips"
    );
  }

  fn loopback() -> NetworkInterface {
    NetworkInterface {
      name: "lo".to_string(),
      description: "loopback".to_string(),
      index: 0,
      mac: None,
      ips: vec![
        IpNetwork::V4(Ipv4Network::new(Ipv4Addr::LOCALHOST, 24).unwrap()),
        IpNetwork::V6(Ipv6Network::new(Ipv6Addr::LOCALHOST, 64).unwrap()),
      ],
      flags: pnet_sys::IFF_MULTICAST as InterfaceType & pnet_sys::IFF_LOOPBACK as InterfaceType,
    }
  }

  fn interface(
    name: impl AsRef<str>,
    index: u32,
    ips: &[IpNetwork],
    flags: &[c_int],
  ) -> NetworkInterface {
    NetworkInterface {
      name: name.as_ref().into(),
      description: String::new(),
      index,
      mac: None,
      ips: ips.to_vec(),
      flags: flags
        .iter()
        .fold(0, |acc, &flag| acc | flag as InterfaceType),
    }
  }
}
