//! mplayer (in progress)
