//! evi: the Sony EVI-D100 camera head over VISCA (work in progress; not registered yet).
