//! jderobot's patch: entry points for jderobot's fuzzing (tests/fuzz.rs), so
//! that arbitrary bytes reach the crate's own datagram parser and fragment
//! assembly, the code a peer's UDP datagram goes through. Not an API.

use std::collections::BTreeMap;

use bytes::Bytes;

use crate::{
  messages::submessages::submessage::WriterSubmessage,
  rtps::{fragment_assembler::FragmentAssembler, Message, SubmessageBody},
  structure::guid::GUID,
};

/// Parses `datagram` as a listener's datagram is parsed: its submessage
/// count, or None when it is refused.
pub fn parse(datagram: &[u8]) -> Option<usize> {
  let m = Message::read_from_buffer(&Bytes::copy_from_slice(datagram)).ok()?;
  Some(m.submessages.len())
}

/// Parses each of `datagrams` and feeds their DATA_FRAGs, in order, to one
/// fragment assembler per writer, as a built-in reader does (samples over
/// its size limit dropped first, as patch 0018's check does); the number of
/// samples completed.
pub fn assemble(datagrams: &[&[u8]]) -> usize {
  let mut assemblers: BTreeMap<GUID, FragmentAssembler> = BTreeMap::new();
  let mut done = 0;
  for d in datagrams {
    let Ok(m) = Message::read_from_buffer(&Bytes::copy_from_slice(d)) else {
      continue;
    };
    for s in m.submessages {
      let SubmessageBody::Writer(WriterSubmessage::DataFrag(df, flags)) = s.body else {
        continue;
      };
      if !crate::rtps::reader::assembles(&df, true) {
        continue;
      }
      let writer = GUID::new_with_prefix_and_id(m.header.guid_prefix, df.writer_id);
      let a = assemblers
        .entry(writer)
        .or_insert_with(|| FragmentAssembler::new(df.fragment_size));
      done += usize::from(a.new_datafrag(&df, flags).is_some());
    }
  }
  done
}
