// Decodes the DDS samples test_live_dds captured off the wire with decoders nobody here wrote
// (Foxglove's ROS 2 CDR reader, its ROS 2 Humble message definitions, its .msg parser reading our
// shipped msg/*.msg) and checks every field against the JSON Lines of the same frames.
//   node ros2_decode.js CAPTURE_DIR FRAMES.jsonl MSG_DIR FRAME_ID
// Prints "ok frames=N people=P joints=J marker_points=M tracked=T inferred=I", or an error and
// exits 1.
"use strict";
const fs = require("fs");
const path = require("path");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");
const { ros2humble } = require("@foxglove/rosmsg-msgs-common");
const { parse, stringify } = require("@foxglove/rosmsg");

const [dir, jsonlPath, msgDir, frameId] = process.argv.slice(2);
const sep = (name) => "\n" + "=".repeat(80) + "\nMSG: " + name + "\n";
// Our message with its dependencies in the full-text form ROS tools use; std_msgs/Header from
// the common definitions.
const text =
  fs.readFileSync(path.join(msgDir, "Skeletons.msg"), "utf8") +
  sep("poseforest_msgs/Skeleton") + fs.readFileSync(path.join(msgDir, "Skeleton.msg"), "utf8") +
  sep("poseforest_msgs/SkeletonJoint") + fs.readFileSync(path.join(msgDir, "SkeletonJoint.msg"), "utf8") +
  sep("std_msgs/Header") + stringify([ros2humble["std_msgs/Header"]]);
const definitions = parse(text, { ros2: true });
const skeletonsReader = new MessageReader(definitions);
const markersReader = new MessageReader([ros2humble["visualization_msgs/MarkerArray"], ...Object.values(ros2humble)]);

let failures = 0;
function check(ok, what) {
  if (!ok && failures++ < 20) console.error("MISMATCH: " + what);
}
// SkeletonJoint.msg's state constants, as the parser read them; the JSON Lines names them.
const jointDef = definitions.find((d) => d.name === "poseforest_msgs/SkeletonJoint");
const constant = (name) => (jointDef.definitions.find((f) => f.isConstant && f.name === name) || {}).value;
const STATES = { not_tracked: constant("NOT_TRACKED"), inferred: constant("INFERRED"), tracked: constant("TRACKED") };
check(STATES.not_tracked === 0 && STATES.inferred === 1 && STATES.tracked === 2,
      `SkeletonJoint.msg constants ${JSON.stringify(STATES)}`);
check(jointDef.definitions.filter((f) => !f.isConstant).map((f) => f.name).join(" ") ===
      "name found tracked confidence position_m pixel state", "SkeletonJoint.msg fields");
const near = (a, b, tol) => Math.abs(a - b) <= tol;

const frames = fs.readFileSync(jsonlPath, "utf8").trim().split("\n").map((l) => JSON.parse(l));
let people = 0, joints = 0, markerPoints = 0, trackedJoints = 0, inferredJoints = 0;
frames.forEach((f, k) => {
  const s = skeletonsReader.readMessage(fs.readFileSync(path.join(dir, `skeletons-${k}.bin`)));
  const m = markersReader.readMessage(fs.readFileSync(path.join(dir, `markers-${k}.bin`)));
  const at = `frame ${k}`;
  check(Number(s.index) === f.index, `${at}: index ${s.index} vs ${f.index}`);
  check(near(s.time_s, f.time_s, 5e-7), `${at}: time_s ${s.time_s} vs ${f.time_s}`);
  check(near(s.header.stamp.sec + s.header.stamp.nanosec * 1e-9, f.time_s, 1e-6), `${at}: stamp`);
  check(s.header.frame_id === frameId, `${at}: frame_id ${s.header.frame_id}`);
  check(s.source === f.source, `${at}: source ${s.source}`);
  check(s.people.length === f.people.length, `${at}: ${s.people.length} people vs ${f.people.length}`);
  // Per person its joints and bones, and its inferred joints when it has some.
  const withInferred = f.people.filter((p) => p.joints.some((j) => j.state === "inferred")).length;
  check(m.markers.length === 1 + 2 * f.people.length + withInferred, `${at}: ${m.markers.length} markers`);
  check(m.markers[0].action === 3, `${at}: first marker not DELETEALL`);
  f.people.forEach((p, i) => {
    const q = s.people[i];
    if (!q) return;
    ++people;
    check(q.id === p.id && q.pixels === p.pixels, `${at} person ${i}: id/pixels`);
    for (let c = 0; c < 3; ++c) check(near(q.centroid_m[c], p.centroid_m[c], 5e-5), `${at} person ${i}: centroid`);
    check(q.joints.length === 16 && p.joints.length === 16, `${at} person ${i}: joint count`);
    const tracked = [], inferred = [];
    p.joints.forEach((j, n) => {
      const r = q.joints[n];
      ++joints;
      check(r.name === j.name, `${at} ${j.name}: name ${r.name}`);
      check(r.tracked === j.tracked, `${at} ${j.name}: tracked`);
      check(j.state in STATES && r.state === STATES[j.state], `${at} ${j.name}: state ${r.state} vs ${j.state}`);
      check((r.state === STATES.tracked) === r.tracked, `${at} ${j.name}: state ${r.state} vs tracked ${r.tracked}`);
      check(r.state !== STATES.inferred || (r.found && !r.tracked), `${at} ${j.name}: inferred, not found or tracked`);
      check(r.found === (j.position_m !== null), `${at} ${j.name}: found`);
      check(near(r.confidence, j.confidence, 5e-5), `${at} ${j.name}: confidence ${r.confidence} vs ${j.confidence}`);
      if (j.position_m !== null) {
        for (let c = 0; c < 3; ++c) check(near(r.position_m[c], j.position_m[c], 5e-5), `${at} ${j.name}: position`);
        for (let c = 0; c < 2; ++c) check(near(r.pixel[c], j.pixel[c], 0.051), `${at} ${j.name}: pixel`);
      }
      if (j.tracked) tracked.push(j);
      if (j.state === "inferred") inferred.push(j);
    });
    trackedJoints += tracked.length;
    inferredJoints += inferred.length;
    // Markers: 2 id = the tracked joints (SPHERE_LIST), 2 id + 1 = bones (LINE_LIST); namespace
    // poseforest_inferred, 2 id = the inferred joints (SPHERE_LIST), only if there are some.
    const marker = (ns, id) => m.markers.find((x) => x.ns === ns && x.id === id);
    const spheres = marker("poseforest", 2 * p.id);
    const bones = marker("poseforest", 2 * p.id + 1);
    const hidden = marker("poseforest_inferred", 2 * p.id);
    check(spheres && spheres.type === 7 && bones && bones.type === 5, `${at}: person ${p.id}'s markers`);
    if (!spheres || !bones) return;
    check(spheres.header.frame_id === frameId && spheres.ns === "poseforest", `${at}: marker header/ns`);
    check(spheres.points.length === tracked.length, `${at}: ${spheres.points.length} spheres vs ${tracked.length} tracked`);
    tracked.forEach((j, n) => {
      const pt = spheres.points[n];
      if (pt) check(near(pt.x, j.position_m[0], 5e-5) && near(pt.y, j.position_m[1], 5e-5) && near(pt.z, j.position_m[2], 5e-5),
                    `${at}: sphere ${j.name}`);
    });
    check(bones.points.length % 2 === 0, `${at}: odd LINE_LIST`);
    for (const pt of bones.points)
      check(tracked.some((j) => near(pt.x, j.position_m[0], 5e-5) && near(pt.y, j.position_m[1], 5e-5)), `${at}: bone end`);
    check(["r", "g", "b"].every((c) => spheres.color[c] === bones.color[c]) && spheres.color.a === 1, `${at}: colours`);
    markerPoints += spheres.points.length + bones.points.length;
    check(!hidden === (inferred.length === 0), `${at}: person ${p.id}: inferred marker with ${inferred.length} inferred joints`);
    if (!hidden) return;
    check(hidden.type === 7 && hidden.action === 0 && hidden.header.frame_id === frameId, `${at}: inferred marker type`);
    check(hidden.scale.x < spheres.scale.x && hidden.color.a < 1, `${at}: inferred marker smaller, translucent`);
    check(["r", "g", "b"].some((c) => hidden.color[c] !== spheres.color[c]), `${at}: inferred marker colour`);
    check(hidden.points.length === inferred.length, `${at}: ${hidden.points.length} inferred spheres vs ${inferred.length}`);
    inferred.forEach((j, n) => {
      const pt = hidden.points[n];
      check(pt && near(pt.x, j.position_m[0], 5e-5) && near(pt.y, j.position_m[1], 5e-5) && near(pt.z, j.position_m[2], 5e-5),
            `${at}: inferred sphere ${j.name}`);
    });
    // No bone ends at an inferred joint.
    for (const pt of bones.points)
      check(!inferred.some((j) => near(pt.x, j.position_m[0], 5e-5) && near(pt.y, j.position_m[1], 5e-5) &&
                                 near(pt.z, j.position_m[2], 5e-5)), `${at}: a bone to an inferred joint`);
    markerPoints += hidden.points.length;
  });
});
if (failures) {
  console.error(`${failures} mismatches`);
  process.exit(1);
}
console.log(`ok frames=${frames.length} people=${people} joints=${joints} marker_points=${markerPoints} ` +
            `tracked=${trackedJoints} inferred=${inferredJoints}`);
