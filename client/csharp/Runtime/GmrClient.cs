// A plain C# client of gmr-server over its C ABI (GmrNative.cs). Nothing here
// depends on an engine: a Unity component (Unity/GmrLiveLink.cs), a console
// program or a test call the same classes.
//
//   using (var client = Gmr.Client.Connect("127.0.0.1", 7400))
//   {
//       uint view = client.CreateView("walk");
//       client.SetRoots(view, "LeftFoot");
//       var options = new Gmr.SubscribeOptions { Conventions = Gmr.Conventions.Unity, LocalTransforms = true };
//       using (var sub = client.Subscribe(view, options))
//           while (...) if (sub.Poll()) use(sub.Frame, sub.Positions, sub.LocalRotations, ...);
//   }
using System;
using System.Collections.Generic;
using System.Runtime.InteropServices;

namespace Gmr
{
    /// <summary>An engine's axes, handedness and unit (docs/protocol.md, "Conventions").</summary>
    public enum Conventions
    {
        Native = 0,   // the motion's own
        Unreal = 1,   // Z up, X forward, left-handed, cm
        Unity = 2,    // Y up, Z forward, left-handed, m
        Blender = 3,  // Z up, -Y forward, right-handed, m
        Godot = 4,    // Y up, -Z forward, right-handed, m
    }

    /// <summary>A BVH channel (the C ABI's gmr_channel).</summary>
    public enum Channel
    {
        XPosition = 0,
        YPosition = 1,
        ZPosition = 2,
        XRotation = 3,
        YRotation = 4,
        ZRotation = 5,
    }

    /// <summary>One joint of a rig to retarget onto: parents before children, the offset from its
    /// parent (a root: its position) in the motion's axes.</summary>
    public struct RigJoint
    {
        public string Name;
        public int Parent;
        public double OffsetX, OffsetY, OffsetZ;
        public Channel[] Channels;

        public RigJoint(string name, int parent, double x, double y, double z, params Channel[] channels)
        {
            Name = name;
            Parent = parent;
            OffsetX = x;
            OffsetY = y;
            OffsetZ = z;
            Channels = channels;
        }
    }

    /// <summary>The C ABI's gmr_status.</summary>
    public enum Status
    {
        Ok = 0,
        NoFrame = 1,
        Ended = 2,
        InvalidArgument = 10,
        Connection = 11,
        BadRequest = 12,
        NotFound = 13,
        FailedPrecondition = 14,
        ResourceExhausted = 15,
        PermissionDenied = 16,
        Internal = 17,
    }

    /// <summary>A call the server or the library refused: its status and the library's message.</summary>
    public sealed class GmrException : Exception
    {
        public Status Status { get; private set; }

        public GmrException(Status status, string message) : base(message) { Status = status; }

        internal static void Check(int status, string what)
        {
            if (status == (int)Status.Ok) return;
            throw new GmrException((Status)status, what + ": " + Native.LastError());
        }
    }

    public struct MotionInfo
    {
        public string Name;
        public int JointCount;
        public ulong FrameCount;
        public double FrameTime;      // seconds
        public double MetresPerUnit;  // 0: unknown
    }

    public struct JointInfo
    {
        public string Name;
        public int Parent;               // -1: a root
        public double[] RestTranslation; // x, y, z from the parent, in the subscription's conventions
        public double[] RestRotation;    // x, y, z, w
    }

    public sealed class SubscribeOptions
    {
        public double RateHz;            // 0: the motion's rate times Speed
        public double Speed = 1.0;
        public bool Loop = true;
        public bool Udp;
        public bool Float64 = true;
        public bool LocalTransforms;
        public bool Orientations;
        public ulong MaxFrames;          // 0: no limit
        public uint StartFrame;
        public uint EndFrame;            // 0: the motion's end
        public Conventions Conventions = Conventions.Native;
        public double SourceMetresPerUnit; // the motion's unit when the library does not know it; 0: the library's
        public uint MaxStalenessMs;      // 0: 100 ms
    }

    /// <summary>
    /// A connection. Not thread-safe: call it from one thread (a game loop's).
    /// Dispose() ends its subscriptions first, then the connection.
    /// </summary>
    public sealed class Client : IDisposable
    {
        private IntPtr handle;
        // Open subscriptions: the C ABI's subscription points at its client, so
        // they end before it does, in Dispose and in the finalizer alike.
        private readonly List<Subscription> subscriptions = new List<Subscription>();

        private Client(IntPtr handle) { this.handle = handle; }

        /// <summary>Connects and says Hello (TCP port of gmr-server, 7400 by default).</summary>
        public static Client Connect(string host = "127.0.0.1", int port = 7400, string token = null)
        {
            if (port <= 0 || port > 65535) throw new ArgumentOutOfRangeException("port", "a TCP port is 1 to 65535");
            if (Native.gmr_abi_version() != Native.AbiVersion)
                throw new GmrException(Status.Internal, "libgmr_client_c has ABI version " + Native.gmr_abi_version() +
                                       ", this package was written for " + Native.AbiVersion);
            IntPtr h;
            GmrException.Check(Native.gmr_connect(Native.Utf8(host), (ushort)port, Native.Utf8(token), out h),
                               "connect to " + host + ":" + port);
            return new Client(h);
        }

        private IntPtr Handle
        {
            get
            {
                if (handle == IntPtr.Zero) throw new ObjectDisposedException("Gmr.Client");
                return handle;
            }
        }

        public MotionInfo[] ListMotions()
        {
            UIntPtr count;
            GmrException.Check(Native.gmr_list_motions(Handle, null, UIntPtr.Zero, out count), "list motions");
            // The library may grow between the two calls: ask again until it fits.
            while (true)
            {
                var raw = new Native.MotionInfo[(int)count];
                UIntPtr now;
                GmrException.Check(Native.gmr_list_motions(Handle, raw, (UIntPtr)raw.Length, out now), "list motions");
                if ((ulong)now > (ulong)raw.Length) { count = now; continue; }
                var motions = new MotionInfo[(int)now];
                for (int i = 0; i < motions.Length; i++)
                {
                    motions[i] = new MotionInfo
                    {
                        Name = Native.FromUtf8(raw[i].name), JointCount = (int)raw[i].joint_count,
                        FrameCount = raw[i].frame_count, FrameTime = raw[i].frame_time,
                        MetresPerUnit = raw[i].metres_per_unit,
                    };
                }
                return motions;
            }
        }

        public uint CreateView(string motion)
        {
            uint view;
            GmrException.Check(Native.gmr_create_view(Handle, Native.Utf8(motion), out view), "create a view of " + motion);
            return view;
        }

        public void CloseView(uint view) { GmrException.Check(Native.gmr_close_view(Handle, view), "close view " + view); }
        public void ShiftRoot(uint view, string joint) { GmrException.Check(Native.gmr_shift_root(Handle, view, Native.Utf8(joint)), "shift the root to " + joint); }
        public void Split(uint view, string joint) { GmrException.Check(Native.gmr_split(Handle, view, Native.Utf8(joint)), "split at " + joint); }
        public void Join(uint view, string root) { GmrException.Check(Native.gmr_join(Handle, view, Native.Utf8(root)), "join " + root); }
        public void StripDummies(uint view) { GmrException.Check(Native.gmr_strip_dummies(Handle, view), "strip dummies"); }

        /// <summary>The motion seen from a joint (its bone frame); null or "": world coordinates.</summary>
        public void SetViewpoint(uint view, string joint)
        {
            GmrException.Check(Native.gmr_set_viewpoint(Handle, view, Native.Utf8(joint ?? "")), "view from " + joint);
        }

        /// <summary>Puts the view's motion on your character's rig (docs/retarget.md): its joints
        /// parents first, in the motion's axes (Y up) with BVH channels; `reference`: the rig's
        /// channel values in a pose it stands in when its rest pose does not (null: the rest
        /// pose); the maps role -> joint name (null: the built-in namings); `metresPerUnit`: the
        /// rig's unit (0: the motion's). Subscriptions then get the rig's joints.</summary>
        public void Retarget(uint view, RigJoint[] rig, double[] reference = null,
                             System.Collections.Generic.IDictionary<string, string> rigMap = null,
                             System.Collections.Generic.IDictionary<string, string> sourceMap = null,
                             double metresPerUnit = 0)
        {
            if (rig == null) throw new ArgumentNullException(nameof(rig));
            var owned = new System.Collections.Generic.List<IntPtr>();
            try
            {
                var joints = new Native.PublishJoint[rig.Length];
                for (int i = 0; i < rig.Length; i++)
                {
                    RigJoint j = rig[i];
                    if (j.Channels == null || j.Channels.Length > 6)
                        throw new ArgumentException("rig joint " + i + " ('" + j.Name + "'): 0 to 6 channels");
                    joints[i].name = Native.Utf8Alloc(j.Name, owned);
                    joints[i].parent = j.Parent;
                    joints[i].offset = new[] { j.OffsetX, j.OffsetY, j.OffsetZ };
                    joints[i].channel_count = (uint)j.Channels.Length;
                    joints[i].channels = new int[6];
                    for (int c = 0; c < j.Channels.Length; c++) joints[i].channels[c] = (int)j.Channels[c];
                }
                Native.RoleJoint[] rigEntries = RoleEntries(rigMap, owned), sourceEntries = RoleEntries(sourceMap, owned);
                double[] pose = reference ?? new double[0];
                GmrException.Check(Native.gmr_retarget_mapped(Handle, view, joints, (UIntPtr)joints.Length, pose,
                                                              (UIntPtr)pose.Length, rigEntries, (UIntPtr)rigEntries.Length,
                                                              sourceEntries, (UIntPtr)sourceEntries.Length, metresPerUnit),
                                   "retarget view " + view);
            }
            finally
            {
                foreach (IntPtr p in owned) Marshal.FreeHGlobal(p);
            }
        }

        static Native.RoleJoint[] RoleEntries(System.Collections.Generic.IDictionary<string, string> map,
                                              System.Collections.Generic.List<IntPtr> owned)
        {
            var entries = new Native.RoleJoint[map == null ? 0 : map.Count];
            int k = 0;
            if (map != null)
                foreach (var e in map)
                {
                    entries[k].role = Native.Utf8Alloc(e.Key, owned);
                    entries[k].joint = Native.Utf8Alloc(e.Value, owned);
                    k++;
                }
            return entries;
        }

        /// <summary>Makes exactly these joints the view's roots.</summary>
        public void SetRoots(uint view, params string[] roots)
        {
            var pointers = new IntPtr[roots.Length];
            try
            {
                for (int i = 0; i < roots.Length; i++)
                {
                    byte[] bytes = Native.Utf8(roots[i]);
                    pointers[i] = Marshal.AllocHGlobal(bytes.Length);
                    Marshal.Copy(bytes, 0, pointers[i], bytes.Length);
                }
                GmrException.Check(Native.gmr_set_roots(Handle, view, pointers, (UIntPtr)pointers.Length),
                                   "set the roots to " + string.Join(",", roots));
            }
            finally
            {
                foreach (IntPtr p in pointers)
                    if (p != IntPtr.Zero) Marshal.FreeHGlobal(p);
            }
        }

        /// <summary>Positions of frames [begin, end) in an engine's conventions: frame-major, 3 per joint.</summary>
        public double[] QueryPositions(uint view, uint begin, uint end, Conventions conventions, out int jointCount)
        {
            UIntPtr joints;
            // An array of no capacity: refused for its size, with the joint count set.
            int status = Native.gmr_query_positions(Handle, view, begin, end, (int)conventions, new double[1], UIntPtr.Zero,
                                                    out joints);
            if (status != (int)Status.InvalidArgument || joints == UIntPtr.Zero)
                GmrException.Check(status, "query frames " + begin + " to " + end);
            var positions = new double[(int)(end - begin) * (int)joints * 3];
            GmrException.Check(Native.gmr_query_positions(Handle, view, begin, end, (int)conventions, positions,
                                                          (UIntPtr)positions.Length, out joints),
                               "query frames " + begin + " to " + end);
            jointCount = (int)joints;
            return positions;
        }

        public Subscription Subscribe(uint view, SubscribeOptions options)
        {
            var o = new Native.SubscribeOptions();
            Native.gmr_subscribe_options_init(ref o);
            o.rate_hz = options.RateHz;
            o.speed = options.Speed;
            o.loop = options.Loop ? 1 : 0;
            o.udp = options.Udp ? 1 : 0;
            o.float64 = options.Float64 ? 1 : 0;
            o.local_transforms = options.LocalTransforms ? 1 : 0;
            o.orientations = options.Orientations ? 1 : 0;
            o.max_frames = options.MaxFrames;
            o.start_frame = options.StartFrame;
            o.end_frame = options.EndFrame;
            o.preset = (int)options.Conventions;
            o.source_metres_per_unit = options.SourceMetresPerUnit;
            o.max_staleness_ms = options.MaxStalenessMs;
            IntPtr s;
            GmrException.Check(Native.gmr_subscribe(Handle, view, ref o, out s), "subscribe to view " + view);
            var subscription = new Subscription(this, s);
            subscriptions.Add(subscription);
            return subscription;
        }

        internal void Forget(Subscription subscription) { subscriptions.Remove(subscription); }

        private void Close()
        {
            foreach (Subscription s in subscriptions.ToArray()) s.Release();
            subscriptions.Clear();
            if (handle != IntPtr.Zero) Native.gmr_disconnect(handle);
            handle = IntPtr.Zero;
        }

        public void Dispose()
        {
            Close();
            GC.SuppressFinalize(this);
        }

        ~Client() { Close(); }
    }

    /// <summary>
    /// A running subscription. Poll() once per tick: it copies the newest frame
    /// that arrived into Positions (and the other arrays asked for), never
    /// waiting. When the view's skeleton changes (a root shifted while it
    /// streams), SkeletonChanged is set and Joints already describes the new one.
    /// </summary>
    public sealed class Subscription : IDisposable
    {
        private readonly Client client;
        private IntPtr handle;
        private Native.Frame frame;

        public JointInfo[] Joints { get; private set; }
        public double[] Positions { get; private set; }         // 3 per joint
        public double[] Orientations { get; private set; }      // x, y, z, w per joint (Orientations asked)
        public double[] LocalRotations { get; private set; }    // x, y, z, w relative to the parent (LocalTransforms)
        public double[] LocalTranslations { get; private set; } // x, y, z in the parent's frame (LocalTransforms)
        public bool Ended { get; private set; }
        public string EndReason { get; private set; }
        /// <summary>Metres per unit of Positions and the translations: 1 in Unity's conventions when the
        /// motion's unit is known; 0 when it is not (the numbers are the file's: set SourceMetresPerUnit).</summary>
        public double MetresPerUnit { get; private set; }

        public ulong FrameIndex { get { return frame.frame_index; } }
        public double MotionTime { get { return frame.motion_time; } }
        public ulong Sequence { get { return frame.sequence; } }
        public uint SkeletonVersion { get { return frame.skeleton_version; } }
        public bool SkeletonChanged { get { return frame.skeleton_changed != 0; } }
        public bool HasLocalTransforms { get { return frame.has_local_transforms != 0; } }
        public bool HasOrientations { get { return frame.has_orientations != 0; } }

        internal Subscription(Client client, IntPtr handle)
        {
            this.client = client;
            this.handle = handle;
            double unit;
            GmrException.Check(Native.gmr_subscription_metres_per_unit(handle, out unit), "read the unit");
            MetresPerUnit = unit;
            ReadJoints();
        }

        private IntPtr Handle
        {
            get
            {
                if (handle == IntPtr.Zero) throw new ObjectDisposedException("Gmr.Subscription");
                return handle;
            }
        }

        // The skeleton, and arrays sized for it; `keep` copies what the last
        // poll wrote (a frame of the new skeleton, read before it).
        private void ReadJoints(bool keep = false)
        {
            UIntPtr count;
            GmrException.Check(Native.gmr_subscription_joint_count(Handle, out count), "read the skeleton");
            var joints = new JointInfo[(int)count];
            for (int i = 0; i < joints.Length; i++)
            {
                var raw = new Native.JointInfo();
                GmrException.Check(Native.gmr_subscription_joint(Handle, (UIntPtr)i, ref raw), "read joint " + i);
                joints[i] = new JointInfo
                {
                    Name = Native.FromUtf8(raw.name), Parent = raw.parent,
                    RestTranslation = raw.rest_translation, RestRotation = raw.rest_rotation,
                };
            }
            Joints = joints;
            Positions = Resized(Positions, 3 * joints.Length, keep);
            Orientations = Resized(Orientations, 4 * joints.Length, keep);
            LocalRotations = Resized(LocalRotations, 4 * joints.Length, keep);
            LocalTranslations = Resized(LocalTranslations, 3 * joints.Length, keep);
        }

        private static double[] Resized(double[] old, int length, bool keep)
        {
            if (old != null && old.Length == length) return old;
            var fresh = new double[length];
            if (keep && old != null) Array.Copy(old, fresh, Math.Min(old.Length, length));
            return fresh;
        }

        /// <summary>True when a new frame was copied; false when none arrived since the last poll, or it ended.</summary>
        public bool Poll()
        {
            if (Ended) return false;
            while (true)
            {
                int status = Native.gmr_poll_frame(Handle, ref frame, Positions, Orientations, LocalRotations,
                                                   LocalTranslations, (UIntPtr)Joints.Length);
                if (status == (int)Status.Ok)
                {
                    if (frame.skeleton_changed != 0) ReadJoints(keep: true);
                    return true;
                }
                if (status == (int)Status.NoFrame) return false;
                if (status == (int)Status.Ended)
                {
                    Ended = true;
                    EndReason = Native.LastError();
                    return false;
                }
                // The arrays are too small: the skeleton grew. Read it, then poll again.
                if (status == (int)Status.InvalidArgument)
                {
                    int before = Joints.Length;
                    ReadJoints();
                    if (Joints.Length > before) continue;
                }
                GmrException.Check(status, "poll a frame");
            }
        }

        /// <summary>Frames received, and of them replaced before a poll took them.</summary>
        public void Counts(out ulong received, out ulong replaced)
        {
            GmrException.Check(Native.gmr_subscription_counts(Handle, out received, out replaced), "read the counts");
        }

        /// <summary>Milliseconds from the server encoding the last polled frame to this host receiving it (one clock).</summary>
        public double LatencyMs()
        {
            long send, write, receive;
            GmrException.Check(Native.gmr_last_frame_times(Handle, out send, out write, out receive), "read frame times");
            return send == 0 || receive == 0 ? 0.0 : (receive - send) / 1e6;
        }

        internal void Release()
        {
            if (handle != IntPtr.Zero) Native.gmr_unsubscribe(handle);
            handle = IntPtr.Zero;
        }

        /// <summary>Stops it. (No finalizer: one left open ends with its Client.)</summary>
        public void Dispose()
        {
            Release();
            client.Forget(this);
        }
    }
}
