//! Attitude estimation as the Spinal firmware runs it (complementary filter).
