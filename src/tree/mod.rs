//! Kinematic trees: bodies and joints, CRBA and RNEA generic over the scalar type.
